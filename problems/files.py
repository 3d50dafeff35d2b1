"""Problem files in ``.npz`` (docs/problem-files.md): ``A`` (rows x n, float64), ``lower``,
``upper`` (rows,), ``level`` (rows, int, nondecreasing), ``n`` (scalar int);
optional ``names`` (one per level) and ``x0``. Load/save round-trips exactly
(``names`` is always written so that empty trailing levels survive). The
loader checks every array's shape and dtype from the ``.npy`` headers, and
their total size against the machine's memory, before it reads any data.
"""

from __future__ import annotations

import difflib
import math
import os
import zipfile

import numpy as np

from hikbench.problems.errors import InvalidHierarchyError, ProblemFileError, ProblemTooLargeError
from hikbench.problems.hierarchy import MEMORY_BYTES, Hierarchy

__all__ = ["load", "load_npz", "save", "save_npz"]

_REQUIRED = ("A", "lower", "upper", "level", "n")
_NUMERIC = ("A", "lower", "upper", "x0")  # real numbers (level and n: integers, checked below)


def _array(z, key: str, path) -> np.ndarray:
    """One array of an open npz; an object (pickled) array is refused by name,
    a damaged one (its data cut short) names the array and numpy's reason."""
    try:
        return z[key]
    except ValueError as err:
        if "allow_pickle" in str(err):  # allow_pickle=False: the array holds Python objects
            raise ProblemFileError(f"{path}: {key} must be a numeric array; it holds Python objects "
                                   f"(not read, for safety)") from err
        raise ProblemFileError(f"{path}: array {key} cannot be read ({err})") from err


#: the compression methods numpy.savez and savez_compressed write (zipfile reads no other without extras)
_ZIP_METHODS = {zipfile.ZIP_STORED: "stored", zipfile.ZIP_DEFLATED: "deflated"}


def check_zip_members(path, zf: zipfile.ZipFile, limit: int) -> None:
    """ProblemFileError naming the member of the npz archive ``zf`` (the file ``path``) that
    is encrypted, compressed by another method than numpy writes, or whose uncompressed
    size, from its directory entry, is larger than ``limit`` bytes: checked before any
    member is read (zipfile would raise RuntimeError or NotImplementedError, or inflate it whole)."""
    for info in zf.infolist():
        if info.flag_bits & 0x1:
            raise ProblemFileError(f"{path}: member {info.filename!r} is encrypted: expected the arrays "
                                   f"numpy.savez writes")
        if info.compress_type not in _ZIP_METHODS:
            raise ProblemFileError(f"{path}: member {info.filename!r} uses zip compression method "
                                   f"{info.compress_type}: expected {' or '.join(_ZIP_METHODS.values())} "
                                   f"(numpy.savez, savez_compressed)")
        if info.file_size > limit:
            raise ProblemFileError(f"{path}: member {info.filename!r} holds {info.file_size} bytes: expected "
                                   f"at most {limit}")


def _headers(path) -> dict:
    """{array name: (shape, dtype)} of every ``.npy`` member of the npz, read from
    the members' headers only (numpy.lib.format; nothing is decompressed past them)."""
    out = {}
    with zipfile.ZipFile(path) as zf:
        check_zip_members(path, zf, MEMORY_BYTES // 2)
        for member in zf.namelist():
            if not member.endswith(".npy"):
                continue
            with zf.open(member) as f:
                version = np.lib.format.read_magic(f)
                if version not in ((1, 0), (2, 0)):
                    raise ProblemFileError(f"{path}: array {member[:-4]} has .npy format version "
                                           f"{version[0]}.{version[1]}: expected 1.0 or 2.0")
                read = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                    np.lib.format.read_array_header_2_0
                shape, _, dtype = read(f, max_header_size=10000)
            out[member[:-4]] = (shape, dtype)
    return out


def _check_headers(path, headers: dict) -> None:
    """Refuse, from the headers alone, arrays of Python objects or of the wrong kind or
    number of dimensions, and arrays together larger than half this machine's memory."""
    for key, (shape, dtype) in headers.items():
        if dtype.hasobject:
            raise ProblemFileError(f"{path}: {key} must be a numeric array; it holds Python objects "
                                   f"(not read, for safety)")
        if key in _NUMERIC and dtype.kind not in "iuf":
            raise ProblemFileError(f"{path}: {key} must be a numeric array (float64); got dtype {dtype}")
    if headers["n"][0] != () or headers["n"][1].kind not in "iu":
        raise ProblemFileError(f"{path}: n must be a scalar integer; got shape {headers['n'][0]} "
                               f"and dtype {headers['n'][1]}")
    expected = {"A": ("(rows, n)", 2), "lower": ("(rows,)", 1), "upper": ("(rows,)", 1), "level": ("(rows,)", 1),
                "x0": ("(n,)", 1), "names": ("(levels,)", 1)}
    for key, (dims, ndim) in expected.items():
        if key in headers and len(headers[key][0]) != ndim:
            raise ProblemFileError(f"{path}: {key} has shape {headers[key][0]}: expected {dims}")
    need = sum(math.prod(shape) * dtype.itemsize for shape, dtype in headers.values())
    if need > MEMORY_BYTES // 2:
        raise ProblemTooLargeError(f"{path}: its arrays need {need / 2**30:.3g} GiB, more than half of this "
                                   f"machine's {MEMORY_BYTES / 2**30:.3g} GiB of memory")


def _check_shapes(path, headers: dict, n: int) -> None:
    """Refuse, from the headers and ``n``, arrays whose shapes disagree: A of
    (rows, n), lower, upper and level of (rows,), x0 of (n,)."""
    rows = headers["A"][0][0]
    want = {"A": (rows, n), "lower": (rows,), "upper": (rows,), "level": (rows,), "x0": (n,)}
    for key, shape in want.items():
        if key in headers and tuple(headers[key][0]) != shape:
            raise ProblemFileError(f"{path}: {key} has shape {tuple(headers[key][0])}: expected {shape} "
                                   f"(n = {n}, rows = {rows}, the rows of A)")


def save_npz(h: Hierarchy, path: str | os.PathLike) -> None:
    """Write h to ``path`` (``.npz``, uncompressed)."""
    arrays = {"A": h.A, "lower": h.lower, "upper": h.upper, "level": h.level, "n": np.int64(h.n),
              "names": np.array(h.names, dtype=str)}
    if h.x0 is not None:
        arrays["x0"] = h.x0
    try:
        with open(path, "wb") as f:  # np.savez would append .npz to a str path without it
            np.savez(f, **arrays)
    except OSError as err:
        raise ProblemFileError(f"{os.fspath(path)}: cannot write ({err.strerror or err})") from err


def _refuse_unknown(path, headers: dict) -> None:
    """An array whose name the format does not have (a misspelt ``x_0``) is an error
    naming it and the closest known name, not an array silently left unread."""
    known = (*_REQUIRED, "names", "x0")
    for key in headers:
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ProblemFileError(f"{path}: unknown array {key!r}{hint}; expected some of {list(known)}")


def load_npz(path: str | os.PathLike) -> Hierarchy:
    """Read a hierarchy from an ``.npz`` file; raises ProblemFileError when the
    file cannot be read or a key is missing, InvalidHierarchyError when its
    content is not a valid hierarchy."""
    try:
        with open(path, "rb") as f:
            is_zip = zipfile.is_zipfile(f)
    except OSError as err:
        raise ProblemFileError(f"{path}: cannot read ({err.strerror or err})") from err
    if not is_zip:  # also: an .npy or a text file named .npz
        raise ProblemFileError(f"{path}: not a valid .npz file (expected a zip archive of arrays, "
                               "as numpy.savez writes)")
    try:
        headers = _headers(path)
        missing = [k for k in _REQUIRED if k not in headers]
        if missing:
            raise ProblemFileError(f"{path}: missing array(s) {missing}; expected {list(_REQUIRED)}")
        _refuse_unknown(path, headers)
        _check_headers(path, headers)
        with np.load(path, allow_pickle=False) as z:
            n = _array(z, "n", path)
            if np.ndim(n) == 0 and n.dtype.kind in "iu":
                _check_shapes(path, headers, int(n))
            data = {k: _array(z, k, path) for k in z.files}
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as err:  # EOFError: an empty file
        raise ProblemFileError(f"{path}: not a valid .npz file ({err})") from err
    for k in _NUMERIC:
        if k in data and data[k].dtype.kind not in "iuf":
            raise ProblemFileError(f"{path}: {k} must be a numeric array (float64); got dtype {data[k].dtype}")
    names = [str(s) for s in data["names"]] if "names" in data else None
    if np.ndim(data["n"]) != 0 or data["n"].dtype.kind not in "iu":
        raise ProblemFileError(f"{path}: n must be a scalar integer; got {data['n']!r}")
    try:
        return Hierarchy(data["A"], data["lower"], data["upper"], data["level"], n=int(data["n"]),
                         names=names, x0=data.get("x0"))
    except InvalidHierarchyError as err:  # say which file
        raise InvalidHierarchyError(f"{path}: {err}", level=err.level, row=err.row) from err


def load(path: str | os.PathLike) -> Hierarchy:
    """Load a problem by extension: ``.npz`` or SOTH text (``.txt``/``.soth``)."""
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise ProblemFileError(f"{p}: no such file" if not os.path.exists(p) else f"{p}: not a file")
    if p.endswith(".npz"):
        return load_npz(p)
    from hikbench.problems.soth import load_soth  # SOTH text format
    return load_soth(p)


def save(h: Hierarchy, path: str | os.PathLike) -> None:
    """Save by extension: ``.npz`` or SOTH text (anything else)."""
    p = os.fspath(path)
    if p.endswith(".npz"):
        save_npz(h, p)
    else:
        from hikbench.problems.soth import save_soth
        save_soth(h, p)
