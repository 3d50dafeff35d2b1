"""Task-frame aliases of a robot without curated ones, found by name patterns.

A link (a pinocchio BODY frame) name is split into lower-case words at ``_``,
``-``, digits and camelCase (``RWristYawLink`` -> r, wrist, yaw, link); a side
is the word ``right``/``r`` or ``left``/``l``, or a one-letter side prefix
glued to a keyword (``rhand``). An alias takes, among the links with its side
and one of its keywords, those with the first keyword in its list that occurs,
then the shallowest link (fewest frames up to the root) for a hand (the hand,
not a finger), the deepest for a foot and an end effector (the sole, not the
ankle):

=============  ===========================================  =====  ==========
alias          keywords, in preference order                side   which link
=============  ===========================================  =====  ==========
right_hand     hand, gripper, palm, wrist                   right  shallowest
left_hand      hand, gripper, palm, wrist                   left   shallowest
right_foot     sole, foot, ankle                            right  deepest
left_foot      sole, foot, ankle                            left   deepest
head           head                                         none   shallowest
torso          torso, chest, trunk                          none   shallowest
ee             tcp, tool, ee, flange, effector, hand,       none   deepest
               gripper (else the tip of a serial chain)
base           the root link                                -      -
=============  ===========================================  =====  ==========
"""

from __future__ import annotations

import re

import pinocchio as pin

__all__ = ["ALIAS_RULES", "find_frames", "words"]

#: alias -> (keywords in preference order, side or None, pick the "shallowest" or "deepest" link)
ALIAS_RULES: dict[str, tuple[tuple[str, ...], str | None, str]] = {
    "right_hand": (("hand", "gripper", "palm", "wrist"), "right", "shallowest"),
    "left_hand": (("hand", "gripper", "palm", "wrist"), "left", "shallowest"),
    "right_foot": (("sole", "foot", "ankle"), "right", "deepest"),
    "left_foot": (("sole", "foot", "ankle"), "left", "deepest"),
    "head": (("head",), None, "shallowest"),
    "torso": (("torso", "chest", "trunk"), None, "shallowest"),
    "ee": (("tcp", "tool", "ee", "flange", "effector", "hand", "gripper"), None, "deepest"),
}
_SIDES = {"right": "right", "r": "right", "left": "left", "l": "left"}
_WORD = re.compile(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])")


def words(name: str) -> list[str]:
    """``"RWristYawLink"`` -> ``["r", "wrist", "yaw", "link"]``; ``"l_sole"`` -> ``["l", "sole"]``."""
    return [w.lower() for w in _WORD.findall(name)]


def _side_and_keywords(name: str, keywords: set[str]) -> tuple[str | None, set[str]]:
    """The side a link name states (None: none or both) and the keywords it contains."""
    sides, found = set(), set()
    for w in words(name):
        if w in _SIDES:
            sides.add(_SIDES[w])
        elif w in keywords:
            found.add(w)
        elif w[:1] in "rl" and w[1:] in keywords:  # rhand, lsole
            sides.add(_SIDES[w[0]])
            found.add(w[1:])
    return (sides.pop() if len(sides) == 1 else None), found


def _depth(model: pin.Model, frame_id: int) -> int:
    """Frames from ``frame_id`` up to the universe (parentFrame links)."""
    depth = 0
    while frame_id != 0 and depth <= len(model.frames):
        frame_id = model.frames[frame_id].parentFrame
        depth += 1
    return depth


def find_frames(model: pin.Model) -> dict[str, str]:
    """Alias -> link name for the aliases of :data:`ALIAS_RULES` that the links match
    (module docstring), plus ``base`` (the root link)."""
    links = [(i, f.name) for i, f in enumerate(model.frames) if f.type == pin.FrameType.BODY]
    if not links:
        return {}
    depth = {i: _depth(model, i) for i, _ in links}
    found = {"base": min(links, key=lambda link: depth[link[0]])[1]}
    all_keywords = {k for rule in ALIAS_RULES.values() for k in rule[0]}
    tagged = [(i, name, *_side_and_keywords(name, all_keywords)) for i, name in links]
    for alias, (keywords, side, pick) in ALIAS_RULES.items():
        for keyword in keywords:
            match = [(i, name) for i, name, s, kws in tagged if s == side and keyword in kws]
            if match:
                sign = 1 if pick == "shallowest" else -1
                found[alias] = min(match, key=lambda m: (sign * depth[m[0]], m[0]))[1]
                break
    if "ee" not in found and _is_chain(model):
        found["ee"] = max(links, key=lambda link: (depth[link[0]], -link[0]))[1]
    return found


def _is_chain(model: pin.Model) -> bool:
    """Every joint's parent is the joint before it (a serial arm), and there is one."""
    return model.njoints > 1 and all(model.parents[j] == j - 1 for j in range(1, model.njoints))
