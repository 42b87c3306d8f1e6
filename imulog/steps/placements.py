"""Which IMU sits on which body segment, from the trial's own sensor names and placements.

A sensor's placement is read, in order, from its device record (``imulog.device.IMU``: ``placement``,
``location``, ``segment``, ``body_part``, then the device's ``label``, e.g. an APDM Opal's) and from the IMU's
name (``/imu/right_forearm``, as ``imulog convert --device-name 00B421AF=right_forearm`` names it). Names are
compared by words: ``RightUpperArm``, ``upper_arm_r``, ``humerus_r_imu`` and ``UA`` are all an upper arm.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Any

PLACEMENT_KEYS = ("placement", "location", "segment", "body_part", "label")

#: segment -> word sequences that name it (a sequence matches consecutive words of a placement)
SEGMENT_WORDS: dict[str, tuple[tuple[str, ...], ...]] = {
    "upper_arm": (("upper", "arm"), ("upperarm",), ("humerus",), ("ua",), ("bicep",), ("biceps",)),
    "forearm": (("forearm",), ("fore", "arm"), ("lower", "arm"), ("lowerarm",), ("radius",), ("ulna",), ("fa",)),
    "trunk": (("trunk",), ("torso",), ("chest",), ("sternum",), ("thorax",)),
}
#: a wrist sensor is on the distal forearm: the forearm IMU when nothing names the forearm itself
FALLBACK_WORDS: dict[str, tuple[tuple[str, ...], ...]] = {"forearm": (("wrist",),)}
SIDES = {"l": "left", "left": "left", "r": "right", "right": "right"}


def words(text: str) -> list[str]:
    """``RightUpperArm`` / ``upper_arm_r`` / ``Upper Arm`` -> lower-case words (camel case and separators split)."""
    spaced = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", " ", str(text))
    return [w for w in re.split(r"[^a-z0-9]+", spaced.lower()) if w]


def _has(ws: list[str], phrase: tuple[str, ...]) -> bool:
    """``phrase`` as consecutive words, or (5 letters or more) inside the words run together: converters lower-case
    stream names, so ``RightForearm`` arrives as ``rightforearm``."""
    n = len(phrase)
    if any(tuple(ws[i : i + n]) == phrase for i in range(len(ws) - n + 1)):
        return True
    joined = "".join(phrase)
    return len(joined) >= 5 and joined in "".join(ws)


def placements(imus: Sequence[str], metadata: Mapping[str, Mapping[str, Any]]) -> dict[str, list[str]]:
    """IMU -> the texts that say where it is (device-record placements first, then its name)."""
    out: dict[str, list[str]] = {}
    for imu in imus:
        device = metadata.get(f"imulog.device.{imu}") or {}
        out[imu] = [str(device[k]) for k in PLACEMENT_KEYS if device.get(k)] + [imu]
    return out


def side_of(texts: Sequence[str]) -> str | None:
    """``left`` / ``right`` when a placement says so (``l``/``r``/``left``/``right`` as a word), else None."""
    for text in texts:
        ws = words(text)
        for w in ws:
            if w in SIDES:
                return SIDES[w]
        joined = "".join(ws)
        for side in ("left", "right"):
            if joined.startswith(side) or joined.endswith(side):
                return side
    return None


def segment_candidates(segment: str, imus: Sequence[str], metadata: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """The IMUs whose placement names ``segment`` (``upper_arm``, ``forearm``, ``trunk``), in trial order; the
    fallback words (a wrist sensor for the forearm) only when no placement names the segment itself."""
    where = placements(imus, metadata)
    for table in (SEGMENT_WORDS, FALLBACK_WORDS):
        phrases = table.get(segment, ())
        found = [imu for imu in imus if any(_has(words(t), p) for t in where[imu] for p in phrases)]
        if found:
            return found
    return []


def partner(segment: str, other: str, imus: Sequence[str], metadata: Mapping[str, Mapping[str, Any]]) -> str:
    """The IMU on ``segment`` that goes with the IMU ``other`` already chosen (the same side when several)."""
    where = placements(imus, metadata)
    found = [i for i in segment_candidates(segment, imus, metadata) if i != other]
    if len(found) > 1:
        found = [i for i in found if side_of(where[i]) == side_of(where[other])]
    if len(found) != 1:
        seen = "; ".join(f"{i}: {', '.join(dict.fromkeys(where[i]))}" for i in imus) or "no IMU"
        role = segment.replace("_", "-")
        raise ValueError(f"{'no' if not found else 'more than one'} {role} IMU to pair with {other!r} ({seen})")
    return found[0]


def arm_imus(imus: Sequence[str], metadata: Mapping[str, Mapping[str, Any]]) -> tuple[str, str]:
    """(upper-arm IMU, forearm IMU) from placements; one arm of each side is paired by its side.

    Raises ValueError naming the IMUs and their placements when no pair, or more than one, is found."""
    ua = segment_candidates("upper_arm", imus, metadata)
    fa = segment_candidates("forearm", imus, metadata)
    where = placements(imus, metadata)
    if len(ua) == 1 and len(fa) == 1 and ua != fa:
        return ua[0], fa[0]
    pairs = [(u, f) for u in ua for f in fa if u != f and side_of(where[u]) == side_of(where[f])]
    if len(pairs) == 1:
        return pairs[0]
    seen = "; ".join(f"{i}: {', '.join(dict.fromkeys(where[i]))}" for i in imus) or "no IMU"
    if not ua or not fa:
        missing = " and ".join(r for r, c in (("upper-arm", ua), ("forearm", fa)) if not c)
        raise ValueError(f"no {missing} IMU among the trial's sensor names and placements ({seen})")
    raise ValueError(f"more than one arm: upper-arm IMUs {', '.join(ua)}, forearm IMUs {', '.join(fa)} ({seen})")


def placement_side(imu: str, metadata: Mapping[str, Any]) -> tuple[str, str] | None:
    """Which wrist the metadata puts ``imu`` on: ``(left|right, where it says so)``, from the IMU's device
    record and name (:func:`side_of`), else ``imulog.trial["side"]``, else
    ``imulog.anthropometrics["side"]``; None when nothing names a side."""
    device = metadata.get(f"imulog.device.{imu}") or {}
    for text in placements([imu], metadata)[imu]:
        found = side_of([text])
        if found is not None:
            key = next((k for k in PLACEMENT_KEYS if device.get(k) is not None and str(device[k]) == text), None)
            where = f"imulog.device.{imu} {key}" if key else "the IMU's name"
            return found, f"{where} {text!r}"
    for record in ("imulog.trial", "imulog.anthropometrics"):
        found = side_of([str((metadata.get(record) or {}).get("side") or "")])
        if found is not None:
            return found, f"{record} side"
    return None
