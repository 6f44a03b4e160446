"""Read a :class:`Recommendation` out of whatever an LLM wrote.

The paper's format is ``pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0``. Real models wrap it in
prose, markdown, JSON, code fences or bullet lists, change the key order, use ``=`` and degree
signs, or name the moves ``dx`` / ``move_x``. The parser finds every ``key <separator> number``
pair, names the key from the words just before the separator, and takes:

1. the last run of six consecutive pairs that names all six values (an answer line), else
2. the last value found for each key.

Camera values are clamped to their ranges; moves are clamped to [-1, 1] and rounded. Anything it
cannot read gives ``None``; it never raises.
"""

from __future__ import annotations

import math
import re

from pirl.advice.recommendation import Recommendation

__all__ = ["parse_recommendation"]

KEYS: tuple[str, ...] = ("pan", "tilt", "zoom", "dx", "dy", "dz")

# Words that name a key on their own.
_SYNONYMS: dict[str, str] = {
    "pan": "pan",
    "yaw": "pan",
    "tilt": "tilt",
    "pitch": "tilt",
    "zoom": "zoom",
    "magnification": "zoom",
}
for _axis in ("x", "y", "z"):
    for _form in (
        "{a}",
        "d{a}",
        "δ{a}",
        "delta{a}",
        "move{a}",
        "movement{a}",
        "step{a}",
        "{a}move",
        "{a}movement",
        "{a}step",
        "{a}delta",
        "{a}axis",
    ):
        _SYNONYMS[_form.format(a=_axis)] = "d" + _axis

# Words that may stand between a key and its separator, or before the key ("camera pan angle",
# "Tilt (deg)", "move along X axis"), but never name a key themselves.
# fmt: off
_FILLERS: frozenset[str] = frozenset({
    "a", "an", "the", "new", "next", "target", "targeted", "recommended", "recommend",
    "suggested", "suggest", "set", "setting", "value", "values", "angle", "angles", "deg",
    "degree", "degrees", "level", "levels", "factor", "camera", "cam", "gimbal", "move", "moves",
    "movement", "movements", "step", "steps", "delta", "δ", "d", "change", "direction", "dir",
    "axis", "along", "on", "in", "by", "to", "of", "at", "is", "for", "rec", "desired", "final",
    "adjust", "adjustment", "axes"
})
# fmt: on

# A number, possibly signed, possibly without a leading or trailing digit ("-.5", "1.").
_NUMBER = r"[+-]?\s?(?:\d+(?:\.\d*)?|\.\d+)"
# A separator then a number: ":", "=", "|", "->", "=>", a few words, then optional quotes.
_VALUE = re.compile(
    r"(?:=>|->|[:=|]|\b(?:is|to|of|by|at)\b)\s*[\"']?\s*(" + _NUMBER + r")",
    re.ASCII | re.IGNORECASE,
)
# A bracketed triple after a move key: "move: [-1, 0, 0]", "(dx, dy, dz) = (1, 0, -1)".
_TRIPLE = re.compile(
    r"(?:=>|->|[:=]|\b(?:is|to|of|by)\b)\s*[\[(]\s*("
    + _NUMBER
    + r")\s*[,;]\s*("
    + _NUMBER
    + r")\s*[,;]\s*("
    + _NUMBER
    + r")\s*[\])]",
    re.ASCII | re.IGNORECASE,
)
_TRIPLE_KEYS: frozenset[str] = frozenset(
    {"move", "movement", "moves", "direction", "delta", "step", "xyz", "dxyz", "dxdydz", "offset"}
)
# Words that make the key after them a state, not advice ("position x: 3", "current tilt: 40").
# fmt: off
_ABSOLUTE: frozenset[str] = frozenset({
    "position", "pos", "location", "coordinate", "coordinates", "coords", "center", "centre",
    "size", "grid", "current", "drone", "uav", "now", "currently"
})
# fmt: on
# Where a key's context ends on the left.
_DELIMITERS = re.compile(r"[,;\n{}\[\]|]")
_WORD = re.compile(r"[a-zδ]+")
_CONTEXT_CHARS = 48

# Characters models use for the minus sign, and decorations that carry no meaning.
_TRANSLATE = str.maketrans(
    {
        "\u2212": "-",  # minus sign
        "\u2013": "-",  # en dash
        "\u2014": "-",  # em dash
        "\u2010": "-",
        "\u2011": "-",
        "\ufe63": "-",
        "\uff0d": "-",
        "\uff1a": ":",  # full-width colon
        "\uff1d": "=",
        "\u00b0": " ",  # degree sign
        "\u00ba": " ",
        "\u2192": "->",  # arrow
        "*": " ",
        "`": " ",
        "#": " ",
        "\u0394": "\u03b4",  # capital delta -> small delta
        "\u2206": "\u03b4",  # increment sign
        "\u00a0": " ",
        "\t": " ",
        "\r": "\n",
    }
)


def _normalize(text: str) -> str:
    return text.translate(_TRANSLATE)


def _words_before(context: str) -> list[str]:
    """Lower-case words between the last delimiter of ``context`` and its end."""
    cut = max((m.end() for m in _DELIMITERS.finditer(context)), default=0)
    return _WORD.findall(context[cut:][-_CONTEXT_CHARS:].lower())


def _key_of(context: str) -> str | None:
    """The key named by the words just left of a separator, if any.

    Words are read right to left: fillers are skipped, the first other word must name a key, and
    a key preceded by a word like "position" or "current" names a state, not advice.
    """
    words = _words_before(context)
    for i in range(len(words) - 1, -1, -1):
        key = _SYNONYMS.get(words[i])
        if key is not None:
            return None if i > 0 and words[i - 1] in _ABSOLUTE else key
        if words[i] not in _FILLERS:
            return None
    return None


def _is_triple_key(context: str) -> bool:
    """Whether the words left of a bracketed triple name a move ("move", "dx, dy, dz")."""
    words = _words_before(context)
    if words[-3:] in (["x", "y", "z"], ["dx", "dy", "dz"]):
        return len(words) < 4 or words[-4] not in _ABSOLUTE
    if words and words[-1] == "vector":
        words = words[:-1]
    return bool(words) and words[-1] in _TRIPLE_KEYS


def _to_float(text: str) -> float:
    return float(text.replace(" ", ""))


def _pairs(text: str) -> list[tuple[str, float]]:
    """Every recognised ``(key, value)`` pair, in reading order."""
    found: list[tuple[int, str, float]] = []
    taken: list[tuple[int, int]] = []
    for m in _TRIPLE.finditer(text):
        context = text[max(0, m.start() - 2 * _CONTEXT_CHARS) : m.start()]
        # "(x, y, z)" style keys contain delimiters: look at the text before the bracket too.
        context = context.replace(",", " ").replace("(", " ").replace(")", " ")
        if _is_triple_key(context):
            for offset, key in enumerate(("dx", "dy", "dz")):
                found.append((m.start() + offset, key, _to_float(m.group(offset + 1))))
            taken.append((m.start(), m.end()))
    last_end = 0
    for m in _VALUE.finditer(text):
        if any(a <= m.start() < b for a, b in taken):
            continue
        context = text[max(last_end, m.start() - 2 * _CONTEXT_CHARS) : m.start()]
        last_end = m.end()
        key = _key_of(context)
        if key is not None:
            found.append((m.start(), key, _to_float(m.group(1))))
    found.sort(key=lambda item: item[0])
    return [(key, value) for _, key, value in found]


def _choose(pairs: list[tuple[str, float]]) -> dict[str, float] | None:
    """The last run of six pairs naming all six keys, else the last value of each key."""
    for start in range(len(pairs) - len(KEYS), -1, -1):
        window = pairs[start : start + len(KEYS)]
        if {key for key, _ in window} == set(KEYS):
            return dict(window)
    last: dict[str, float] = {}
    for key, value in pairs:
        last[key] = value
    return last if len(last) == len(KEYS) else None


def parse_recommendation(text: str) -> Recommendation | None:
    """The recommendation in ``text``, or ``None`` when not all six values can be read.

    Accepts any case and spacing, any key order, ``:`` / ``=`` / ``->``, JSON, markdown, degree
    signs, decimals, synonyms (``dx``, ``move_x``, ``x``) and text around the answer. Never raises.
    """
    try:
        if not isinstance(text, str) or not text:
            return None
        values = _choose(_pairs(_normalize(text)))
        if values is None or not all(math.isfinite(v) for v in values.values()):
            return None
        return Recommendation.clamped(*(values[key] for key in KEYS))
    except Exception:  # noqa: BLE001 - the contract is "never raises"
        return None
