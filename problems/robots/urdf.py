"""A user's robot from a URDF file, with an optional SRDF, loaded through pinocchio
(``pin.buildModelFromUrdf``; no meshes are read).

Root joint: a free flyer (nq 7, nv 6, named ``root_joint``, or as the SRDF's
floating virtual joint) when ``floating_base`` is true, none when it is false;
when it is not given, a free flyer exactly when the SRDF declares
``<virtual_joint type="floating" .../>`` (MoveIt's convention), else none (a
fixed base). The SRDF's collision pairs are not read: no task uses collision
geometry.

Reference configuration q0 (shape (nq,)): the SRDF ``<group_state>`` named
``reference`` (default: the first in the file), loaded by
``pin.loadReferenceConfigurations``; without an SRDF, pinocchio's neutral
configuration with every bounded joint whose range excludes 0 at the middle of
its range.

Both files are checked before pinocchio reads them (it prints its parse errors
on stderr and fills a wrong SRDF value with zeros): a missing file, text that is
not XML, a root element that is not ``<robot>``, a URDF without ``<link>``, an
SRDF joint the model lacks or a value count that is not the joint's, a q0
outside the joint limits, or pinocchio's own parse error (captured from stderr)
is a one-line :class:`RobotFileError` naming the file.
"""

from __future__ import annotations

import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from hikbench.problems.errors import HikbenchError
from hikbench.problems.schema import short

__all__ = ["RobotFileError", "UrdfModel", "UrdfSource", "is_urdf_path", "load_urdf"]

ROOT_JOINT = "root_joint"  #: name of the free flyer pinocchio adds (as in example-robot-data's SRDFs)


class RobotFileError(HikbenchError, ValueError):
    """A URDF or SRDF file that cannot be read into a robot model."""


def is_urdf_path(ref) -> bool:
    """A robot reference that names a URDF file (``*.urdf``) rather than a robot name."""
    return isinstance(ref, (str, os.PathLike)) and str(ref).lower().endswith(".urdf")


@dataclass(frozen=True)
class UrdfSource:
    """How to load a user's robot: the URDF path, and optionally an SRDF path, the
    root joint (``floating_base``: None = from the SRDF) and the SRDF group_state of q0."""

    urdf: Path
    srdf: Path | None = None
    floating_base: bool | None = None
    reference: str | None = None

    @property
    def name(self) -> str:
        """The robot's name in outputs: the URDF file's stem."""
        return self.urdf.stem


@dataclass(frozen=True, eq=False)
class UrdfModel:
    """What :func:`load_urdf` read: the model, q0 (shape (nq,)) and how both were chosen."""

    model: pin.Model
    q0: np.ndarray
    floating_base: bool
    description: str


def load_urdf(source: UrdfSource) -> UrdfModel:
    """The pinocchio model of ``source`` and its reference configuration (module docstring)."""
    urdf = source.urdf
    _xml_root(urdf, "URDF")
    srdf_root = _xml_root(source.srdf, "SRDF") if source.srdf is not None else None
    floating, why = _root_joint(source, srdf_root)
    root_name = _virtual_joint_name(srdf_root)
    failure = None
    with _StderrCaptured() as said:
        try:
            model = (pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer(), root_name) if floating
                     else pin.buildModelFromUrdf(str(urdf)))
        except (ValueError, RuntimeError) as err:
            failure, said.echo = err, False
    if failure is not None:
        raise RobotFileError(f"{urdf}: pinocchio cannot read this URDF: "
                             f"{_first_error(said.text) or failure}") from failure
    if model.nv == 0:
        raise RobotFileError(f"{urdf}: the model has no joint (nv = 0): expected a movable joint, or a "
                             "floating base (floating_base = true)")
    if srdf_root is not None:
        q0, ref_why = _srdf_reference(model, source, srdf_root)
    else:
        q0, ref_why = _neutral_inside_limits(model), "q0 neutral (no SRDF)"
    return UrdfModel(model, q0, floating, f"URDF {urdf}; {why}; {ref_why}")


def _xml_root(path: Path, file_type: str) -> ET.Element:
    """The root element of an XML file, checked to be ``<robot>``."""
    if not path.is_file():
        raise RobotFileError(f"{path}: no such {file_type} file" + (" (a directory)" if path.is_dir() else ""))
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        raise RobotFileError(f"{path}: not an XML {file_type} file ({err})") from err
    except OSError as err:
        raise RobotFileError(f"{path}: cannot read the {file_type} file: {err.strerror or err}") from err
    if root.tag != "robot":
        raise RobotFileError(f"{path}: the root element is <{root.tag}>; expected <robot> ({file_type})")
    if file_type == "URDF" and root.find("link") is None:
        raise RobotFileError(f"{path}: no <link> element; expected a URDF with at least one link")
    if file_type == "SRDF" and root.find("link") is not None:
        raise RobotFileError(f"{path}: <link> elements at the top: a URDF; expected an SRDF (group_state, "
                             "virtual_joint, ...)")
    return root


def _root_joint(source: UrdfSource, srdf: ET.Element | None) -> tuple[bool, str]:
    """(free flyer?, why): the explicit choice, else the SRDF's virtual joint, else a fixed base."""
    if source.floating_base is not None:
        return source.floating_base, ("floating base (floating_base = true)" if source.floating_base
                                      else "fixed base (floating_base = false)")
    virtual = [] if srdf is None else srdf.findall("virtual_joint")
    joint_types = sorted({v.get("type", "") for v in virtual})
    if len(joint_types) > 1 or (joint_types and joint_types[0] not in ("floating", "fixed")):
        raise RobotFileError(f"{source.srdf}: virtual_joint type {', '.join(map(repr, joint_types))}: expected one "
                             "'floating' or 'fixed' virtual joint (or set floating_base)")
    if joint_types == ["floating"]:
        return True, "floating base (the SRDF's floating virtual_joint)"
    if joint_types == ["fixed"]:
        return False, "fixed base (the SRDF's fixed virtual_joint)"
    return False, "fixed base (floating_base not set, no virtual_joint in an SRDF)"


def _virtual_joint_name(srdf: ET.Element | None) -> str:
    """The name of the SRDF's floating virtual joint (its group_states may set it), else ``root_joint``."""
    for v in [] if srdf is None else srdf.findall("virtual_joint"):
        if v.get("type") == "floating" and v.get("name"):
            return v.get("name")
    return ROOT_JOINT


def _srdf_reference(model: pin.Model, source: UrdfSource, root: ET.Element) -> tuple[np.ndarray, str]:
    """q0 from the SRDF group_state ``source.reference`` (default: the first), checked."""
    srdf = source.srdf
    states = root.findall("group_state")
    names = [s.get("name") for s in states]
    if not states:
        if source.reference is not None:
            raise RobotFileError(f"{srdf}: no <group_state>; expected one named {source.reference!r} (reference)")
        return _neutral_inside_limits(model), "q0 neutral (no group_state in the SRDF)"
    wanted = source.reference or names[0]
    if wanted not in names:
        raise RobotFileError(f"{srdf}: no group_state {wanted!r} (reference); expected one of "
                             f"{', '.join(map(repr, names))}")
    for state in states:  # all of them: pinocchio reads them all (and zero-fills a bad value)
        for joint in state.findall("joint"):
            _check_srdf_joint(model, srdf, state.get("name"), joint)
    loaded = model.copy()
    with _StderrCaptured():
        pin.loadReferenceConfigurations(loaded, str(srdf), False)
    q0 = next(np.array(e.data(), dtype=float) for e in loaded.referenceConfigurations if e.key() == wanted)
    if not pin.isNormalized(model, q0, 1e-6):
        raise RobotFileError(f"{srdf}: group_state {wanted!r}: a quaternion (free flyer) or cos/sin pair "
                             "is not of norm 1")
    _check_within_limits(model, q0, f"{srdf}: group_state {wanted!r}")
    which = "" if source.reference else f" (the first of {len(names)})" if len(names) > 1 else ""
    return q0, f"q0 the SRDF group_state {wanted!r}{which}"


def _check_srdf_joint(model: pin.Model, srdf: Path, state: str, joint: ET.Element) -> None:
    """A group_state joint: a joint of the model, with as many numbers as it takes."""
    import difflib

    name, text = joint.get("name"), joint.get("value", "")
    joints = list(model.names)[1:]
    if name not in joints:
        close = difflib.get_close_matches(str(name), joints, n=3)
        hint = f" (did you mean {' or '.join(map(repr, close))}?)" if close else ""
        raise RobotFileError(f"{srdf}: group_state {state!r}: joint {name!r} is not a joint of the model{hint}; "
                             f"expected one of its {len(joints)} joints")
    jm = model.joints[model.getJointId(name)]
    count = 1 if (jm.nq == 2 and jm.nv == 1) else jm.nq  # a continuous joint takes its angle
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != count or not np.all(np.isfinite(values)):
        raise RobotFileError(f"{srdf}: group_state {state!r}: joint {name!r} value = {short(text)}: expected "
                             f"{count} finite number{'s' if count > 1 else ''}")


def _bounded_coordinates(model: pin.Model):
    """(configuration index, joint name) of the 1-DOF joints with finite limits."""
    lo, hi = np.asarray(model.lowerPositionLimit), np.asarray(model.upperPositionLimit)
    for j in range(1, model.njoints):
        jm = model.joints[j]
        i = jm.idx_q
        if jm.nq == 1 and jm.nv == 1 and np.isfinite(lo[i]) and np.isfinite(hi[i]) and \
                abs(lo[i]) < 1e10 and abs(hi[i]) < 1e10 and lo[i] < hi[i]:
            yield i, model.names[j]


def _neutral_inside_limits(model: pin.Model) -> np.ndarray:
    """pin.neutral, with each bounded coordinate whose range excludes 0 at its midpoint."""
    q = np.array(pin.neutral(model), dtype=float)
    lo, hi = np.asarray(model.lowerPositionLimit), np.asarray(model.upperPositionLimit)
    for i, _ in _bounded_coordinates(model):
        if not lo[i] <= q[i] <= hi[i]:
            q[i] = 0.5 * (lo[i] + hi[i])
    return q


def _check_within_limits(model: pin.Model, q: np.ndarray, where: str) -> None:
    lo, hi = np.asarray(model.lowerPositionLimit), np.asarray(model.upperPositionLimit)
    for i, name in _bounded_coordinates(model):
        if not lo[i] <= q[i] <= hi[i]:
            raise RobotFileError(f"{where}: joint {name!r} = {q[i]:.6g} is outside its limits "
                                 f"[{lo[i]:.6g}, {hi[i]:.6g}]; expected a configuration within the limits")


def _first_error(text: str) -> str:
    """The first ``Error:`` message urdfdom printed, on one line."""
    for line in text.splitlines():
        if line.strip().startswith("Error:"):
            return " ".join(line.split()[1:])
    return " ".join(text.split())[:200]


class _StderrCaptured:
    """Redirect file descriptor 2 (where pinocchio's C++ parsers print) to a temporary
    file for the ``with`` block; ``text`` then holds what was printed. It is written
    back to stderr (nothing is hidden) unless the caller set ``echo = False`` to put
    it in its own error."""

    def __init__(self):
        self.text, self.echo = "", True

    def __enter__(self) -> _StderrCaptured:
        sys.stderr.flush()
        self._saved = os.dup(2)
        self._tmp = tempfile.TemporaryFile()
        os.dup2(self._tmp.fileno(), 2)
        return self

    def __exit__(self, *exc) -> None:
        os.dup2(self._saved, 2)
        os.close(self._saved)
        with self._tmp:
            self._tmp.seek(0)
            self.text = self._tmp.read().decode(errors="replace")
        if self.echo and self.text:
            sys.stderr.write(self.text)
