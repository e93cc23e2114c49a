"""The groups a take is layered onto: names for sets of curves (``--layer TAKE:GROUP``).

A group is one of these, or a comma list of them:

* a hand: ``right``, ``left`` (its 25 curves and its two wrist DOFs); ``all``: every
  hand the puppet has;
* a finger: ``thumb``, ``index``, ``middle``, ``ring``, ``little`` (or ``pinky``), or the
  ``wrist``; on a two-hand puppet prefixed by its hand: ``left.index``, ``right.wrist``
  (a one-hand puppet takes the bare name as its own hand's, or the prefixed one);
* a curve or wrist DOF of the vocabulary (:data:`handrig.hand.ALL_JOINT_NAMES`, e.g.
  ``riIndexMCPy``; ``handrig joints`` lists them).

An unknown name is a ConfigError listing the allowed ones.
"""

from __future__ import annotations

from collections.abc import Collection

from handrig import hand
from handrig.errors import ConfigError

HAND_WORDS: dict[str, hand.Hand] = {"right": "ri", "left": "le"}
PART_WORDS: dict[str, str] = {"thumb": "Thumb", "index": "Index", "middle": "Middle",
                              "ring": "Ring", "little": "Pinky", "pinky": "Pinky",
                              "wrist": "Wrist"}
DEFAULT_FADE_S = 0.5
"""A layer's fade in and out, seconds (``[[layer]] fade_s``, the cues' layers)."""
FADE_RANGE_S = (0.0, 30.0)
OFF = "off"
"""``layer(TAKE, "off")``: the group word that fades a take's layers out."""


def allowed_groups(hands: Collection[str] = hand.HANDS) -> str:
    """What a group may be, for an error message (``hands``: those the puppet has)."""
    two = len(set(hands)) > 1
    fingers = "thumb, index, middle, ring, little, wrist"
    if two:
        fingers = f"left.FINGER or right.FINGER with FINGER one of {fingers}"
    words = ", ".join(w for w, h in HAND_WORDS.items() if h in hands)
    return (f"{words}, all; {fingers}; or a curve name such as riIndexMCPy (`handrig "
            "joints` lists them); or a comma list of these")


def group_joints(group: str, hands: Collection[str] | None = hand.HANDS, *,
                 key: str = "--layer") -> tuple[str, ...]:
    """The curve and DOF names of ``group`` on a puppet driving ``hands`` (``"ri"``,
    ``"le"``), in full-pose order; ConfigError at ``key`` for a name it does not know.
    ``hands=None``: the puppet is not known yet (a show file read before its rig): the
    words are checked, a bare finger taken as either hand's."""
    any_puppet = hands is None
    hands = hand.HANDS if hands is None else tuple(h for h in hand.HANDS if h in hands)
    found: set[str] = set()
    items = [item.strip() for item in group.split(",")]
    if not group.strip() or not all(items):
        raise ConfigError("an empty group", key=key, value=group,
                          allowed=allowed_groups(hands))
    for item in items:
        if any_puppet and item.lower() in PART_WORDS:
            item = f"right.{item.lower()}"
        found.update(_item(item, hands, group, key))
    return tuple(n for n in hand.ALL_JOINT_NAMES if n in found)


def _item(item: str, hands: tuple[str, ...], group: str, key: str) -> list[str]:
    word = item.lower()
    if word == "all":
        return [n for n in hand.ALL_JOINT_NAMES if n[:2] in hands]
    if word in HAND_WORDS:
        return _of_hand(HAND_WORDS[word], "", hands, group, key)
    side, dot, part = word.partition(".")
    if dot and side in HAND_WORDS and part in PART_WORDS:
        return _of_hand(HAND_WORDS[side], PART_WORDS[part], hands, group, key)
    if not dot and word in PART_WORDS:
        if len(hands) > 1:
            raise ConfigError(f"{item!r} names no hand on a two-hand puppet", key=key,
                              value=group, allowed=f"left.{word} or right.{word}")
        return _of_hand(hands[0], PART_WORDS[word], hands, group, key)
    if item in hand.ALL_JOINT_NAMES:
        return _of_hand(item[:2], "", hands, group, key, only=item)
    raise ConfigError(f"unknown group {item!r}", key=key, value=group,
                      allowed=allowed_groups(hands))


def _of_hand(h: str, digit: str, hands: tuple[str, ...], group: str, key: str, *,
             only: str = "") -> list[str]:
    if h not in hands:
        side = "right" if h == "ri" else "left"
        raise ConfigError(f"this puppet has no {side} hand", key=key, value=group,
                          allowed=allowed_groups(hands))
    if only:
        return [only]
    return [n for n in hand.ALL_JOINT_NAMES if n.startswith(h + digit)]
