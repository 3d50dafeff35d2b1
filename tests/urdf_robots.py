"""Small robots written by the tests as URDF (and SRDF) text: a fixed-base 7-joint arm
and a floating-base biped with two 4-joint arms. Their names are not
example-robot-data's; their link names follow no curated alias (the aliases are
found by name patterns: ``r_hand``, ``l_sole``, ``arm_flange``, ``chest``)."""

from __future__ import annotations

from pathlib import Path


def _inertial(mass: float, size: float) -> str:
    i = mass * size * size / 6.0  # a cube of side `size`
    return (f'<inertial><origin xyz="0 0 0"/><mass value="{mass}"/>'
            f'<inertia ixx="{i:.6g}" iyy="{i:.6g}" izz="{i:.6g}" ixy="0" ixz="0" iyz="0"/></inertial>')


def _link(name: str, mass: float = 0.0, size: float = 0.1) -> str:
    return f'<link name="{name}">{_inertial(mass, size) if mass else ""}</link>'


def _joint(name, parent, child, xyz=(0, 0, 0), axis=(0, 0, 1), lower=-2.0, upper=2.0, kind="revolute"):
    limit = f'<limit lower="{lower}" upper="{upper}" velocity="4.0" effort="100"/>' if kind == "revolute" else ""
    ax = f'<axis xyz="{" ".join(map(str, axis))}"/>' if kind == "revolute" else ""
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{" ".join(map(str, xyz))}" rpy="0 0 0"/>{ax}{limit}</joint>')


def arm_urdf() -> str:
    """A 7-joint arm on a fixed base (links 0.3 / 0.3 / 0.1 m), tip link ``arm_flange``."""
    axes = [(0, 0, 1), (0, 1, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1)]
    offsets = [(0, 0, 0.1), (0, 0, 0.1), (0, 0, 0.2), (0, 0, 0.1), (0, 0, 0.2), (0, 0, 0.1), (0, 0, 0.05)]
    parts = [_link("arm_base", 2.0)]
    for k in range(7):
        parent = "arm_base" if k == 0 else f"arm_link{k}"
        parts += [_link(f"arm_link{k + 1}", 1.0), _joint(f"arm_joint{k + 1}", parent, f"arm_link{k + 1}",
                                                          offsets[k], axes[k], -2.5, 2.5)]
    parts += [_link("arm_flange"), _joint("arm_flange_joint", "arm_link7", "arm_flange", (0, 0, 0.05),
                                          kind="fixed")]
    return f'<?xml version="1.0"?>\n<robot name="test_arm">{"".join(parts)}</robot>\n'


def _leg(s: str, y: float) -> list[str]:
    names = [f"{s}_hip_yaw", f"{s}_hip_roll", f"{s}_hip_pitch", f"{s}_knee", f"{s}_ankle_pitch", f"{s}_ankle_roll"]
    axes = [(0, 0, 1), (1, 0, 0), (0, 1, 0), (0, 1, 0), (0, 1, 0), (1, 0, 0)]
    xyz = [(0, y, -0.05), (0, 0, 0), (0, 0, 0), (0, 0, -0.35), (0, 0, -0.35), (0, 0, 0)]
    limits = [(-0.8, 0.8), (-0.5, 0.5), (-1.5, 0.5), (0.0, 2.2), (-1.0, 1.0), (-0.5, 0.5)]
    masses = [1.0, 1.0, 4.0, 3.0, 0.5, 1.0]
    parts, parent = [], "pelvis"
    for name, axis, p, (lo, hi), m in zip(names, axes, xyz, limits, masses):
        parts += [_link(f"{name}_link", m), _joint(f"{name}_joint", parent, f"{name}_link", p, axis, lo, hi)]
        parent = f"{name}_link"
    parts += [_link(f"{s}_sole"), _joint(f"{s}_sole_joint", parent, f"{s}_sole", (0, 0, -0.06), kind="fixed")]
    return parts


def _arm(s: str, y: float) -> list[str]:
    names = [f"{s}_shoulder_pitch", f"{s}_shoulder_roll", f"{s}_elbow", f"{s}_wrist"]
    axes = [(0, 1, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
    xyz = [(0, y, 0.35), (0, 0, 0), (0, 0, -0.25), (0, 0, -0.25)]
    roll = (-1.5, 0.3) if s == "r" else (-0.3, 1.5)
    limits = [(-2.5, 2.5), roll, (-2.2, 0.0), (-1.5, 1.5)]
    masses = [1.0, 2.0, 1.5, 0.5]
    parts, parent = [], "chest"
    for name, axis, p, (lo, hi), m in zip(names, axes, xyz, limits, masses):
        parts += [_link(f"{name}_link", m), _joint(f"{name}_joint", parent, f"{name}_link", p, axis, lo, hi)]
        parent = f"{name}_link"
    parts += [_link(f"{s}_hand", 0.3), _joint(f"{s}_hand_joint", parent, f"{s}_hand", (0, 0, -0.05), kind="fixed")]
    return parts


def biped_urdf() -> str:
    """A biped (legs 0.35 + 0.35 + 0.06 m, arms 0.25 + 0.25 + 0.05 m, 17 joints): the
    free flyer comes from the SRDF's floating virtual joint or ``floating_base``."""
    parts = [_link("pelvis", 8.0, 0.25), _link("chest", 12.0, 0.3),
             _joint("chest_joint", "pelvis", "chest", (0, 0, 0.1), (0, 0, 1), -0.8, 0.8)]
    parts += _leg("l", 0.1) + _leg("r", -0.1) + _arm("l", 0.2) + _arm("r", -0.2)
    return f'<?xml version="1.0"?>\n<robot name="test_biped">{"".join(parts)}</robot>\n'


BENT = {"hip_pitch": -0.4, "knee": 0.8, "ankle_pitch": -0.4, "elbow": -0.5}


def biped_srdf(virtual_joint: bool = True) -> str:
    """A floating virtual joint and a bent-knee ``half_sitting`` group_state (root at 0.7 m)."""
    joints = "".join(f'<joint name="{s}_{j}_joint" value="{v}"/>' for s in "lr" for j, v in BENT.items())
    vj = '<virtual_joint name="root_joint" type="floating" parent_frame="world" child_link="pelvis"/>' \
        if virtual_joint else ""
    root = '<joint name="root_joint" value="0 0 0.7 0 0 0 1"/>' if virtual_joint else ""
    return (f'<?xml version="1.0"?>\n<robot name="test_biped">{vj}'
            f'<group_state name="half_sitting" group="all">{root}{joints}</group_state>'
            f'<disable_collisions link1="pelvis" link2="chest" reason="Adjacent"/></robot>\n')


def write_robots(folder: Path) -> dict[str, Path]:
    """arm.urdf, biped.urdf and biped.srdf in ``folder``; name -> path."""
    folder.mkdir(parents=True, exist_ok=True)
    files = {"arm.urdf": arm_urdf(), "biped.urdf": biped_urdf(), "biped.srdf": biped_srdf()}
    for name, text in files.items():
        (folder / name).write_text(text)
    return {name: folder / name for name in files}
