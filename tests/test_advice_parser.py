"""parse_recommendation: real-looking answers by hand, and property tests that it never raises."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from pirl.advice import Recommendation, parse_recommendation

PAPER = Recommendation(pan=75.0, tilt=45.0, zoom=1.0, dx=-1, dy=0, dz=0)


def rec(pan, tilt, zoom, dx, dy, dz) -> Recommendation:
    return Recommendation(pan=pan, tilt=tilt, zoom=zoom, dx=dx, dy=dy, dz=dz)


# (answer text, expected recommendation): what models write around the requested format.
REAL_ANSWERS = [
    ("pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0", PAPER),
    ("pan: 75, tilt: 45, zoom: 1.0, X: -1, Y: 0, Z: 0", PAPER),
    ("pan:75,tilt:45,zoom:1,X:-1,Y:0,Z:0", PAPER),
    ("PAN: 75, TILT: 45, ZOOM: 1, x: -1, y: 0, z: 0", PAPER),
    ("pan = 75, tilt = 45, zoom = 1.0, X = -1, Y = 0, Z = 0", PAPER),
    ("X: -1, Y: 0, Z: 0, zoom: 1, tilt: 45, pan: 75", PAPER),
    ("pan: 75°, tilt: 45°, zoom: 1.0x, X: -1, Y: 0, Z: 0", PAPER),
    ("pan: 75 degrees, tilt: 45 degrees, zoom: 1.0, X: −1, Y: 0, Z: 0", PAPER),
    ("Recommendation: pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0.", PAPER),
    (
        "Based on the drone's position near the edge, I suggest turning the camera.\n\n"
        "pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0\n\n"
        "This keeps the obstacles out of the way and saves battery.",
        PAPER,
    ),
    ("**pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0**", PAPER),
    ("`pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0`", PAPER),
    ("```\npan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0\n```", PAPER),
    (
        "Here are my recommendations:\n\n- **Pan:** 75°\n- **Tilt:** 45°\n- **Zoom:** 1.0\n"
        "- **X:** -1\n- **Y:** 0\n- **Z:** 0\n\nMoving left explores new ground.",
        PAPER,
    ),
    (
        "1. Pan: 75\n2. Tilt: 45\n3. Zoom: 1\n4. X: -1 (move left)\n5. Y: 0\n6. Z: 0",
        PAPER,
    ),
    ("* pan -> 75\n* tilt -> 45\n* zoom -> 1\n* X -> -1\n* Y -> 0\n* Z -> 0", PAPER),
    (
        '```json\n{"pan": 75, "tilt": 45, "zoom": 1.0, "X": -1, "Y": 0, "Z": 0}\n```',
        PAPER,
    ),
    ('{"pan": "75", "tilt": "45°", "zoom": "1", "dx": "-1", "dy": "0", "dz": "0"}', PAPER),
    (
        '{"camera": {"pan": 75, "tilt": 45, "zoom": 1.0}, "move": {"x": -1, "y": 0, "z": 0}}',
        PAPER,
    ),
    ('{"pan": 75, "tilt": 45, "zoom": 1, "move": [-1, 0, 0]}', PAPER),
    ("pan: 75, tilt: 45, zoom: 1, (dx, dy, dz) = (-1, 0, 0)", PAPER),
    ("pan=75 tilt=45 zoom=1 dx=-1 dy=0 dz=0", PAPER),
    ("pan: 75, tilt: 45, zoom: 1, move_x: -1, move_y: 0, move_z: 0", PAPER),
    ("Pan angle: 75, Tilt angle: 45, Zoom level: 1, Move X: -1, Move Y: 0, Move Z: 0", PAPER),
    ("camera_pan: 75\ncamera_tilt: 45\ncamera_zoom: 1\ndelta_x: -1\ndelta_y: 0\ndelta_z: 0", PAPER),
    ("Pan (deg): 75 | Tilt (deg): 45 | Zoom: 1 | ΔX: -1 | ΔY: 0 | ΔZ: 0", PAPER),
    (
        "| Parameter | Value |\n|---|---|\n| pan | 75 |\n| tilt | 45 |\n| zoom | 1 |\n"
        "| X | -1 |\n| Y | 0 |\n| Z | 0 |",
        PAPER,
    ),
    (
        "Set the pan to 75 degrees, tilt to 45, zoom to 1.0, and move X by -1, Y by 0 and Z by 0.",
        PAPER,
    ),
    ("pan: +75, tilt: 45.0, zoom: 1.00, X: -1.0, Y: 0.0, Z: 0.0", PAPER),
    ("pan：75，tilt：45, zoom：1, X：-1, Y：0, Z：0", PAPER),  # full-width colons
    # The model repeats the drone's state before answering: the answer line wins.
    (
        "Current state: position x: 14, y: 0, z: 2, tilt: 60, pan: 90, zoom: 1.\n"
        "My answer: pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0",
        PAPER,
    ),
    (
        "Following the format pan: 0, tilt: 90, zoom: 1, X: 0, Y: 0, Z: 0, my answer is "
        "pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0",
        PAPER,
    ),
    # Decimals, clamping and rounding.
    ("pan: -37.5, tilt: 12.25, zoom: 0.75, X: 1, Y: -1, Z: 1", rec(-37.5, 12.25, 0.75, 1, -1, 1)),
    ("pan: 120, tilt: 95, zoom: 3, X: 2, Y: -5, Z: 0", rec(90.0, 90.0, 2.0, 1, -1, 0)),
    ("pan: -180, tilt: -10, zoom: 0.1, X: 0, Y: 0, Z: 0", rec(-90.0, 0.0, 0.5, 0, 0, 0)),
    ("pan: 0, tilt: 90, zoom: 2, X: 0.6, Y: -0.4, Z: 0.5", rec(0.0, 90.0, 2.0, 1, 0, 1)),
    ("pan: 0, tilt: 90, zoom: 2, X: -0.5, Y: 0.49, Z: -0.51", rec(0.0, 90.0, 2.0, -1, 0, -1)),
    ("pan: -0, tilt: 0, zoom: .5, X: -0, Y: 0, Z: 0", rec(0.0, 0.0, 0.5, 0, 0, 0)),
]

UNREADABLE = [
    "",
    "   ",
    "I think the drone should fly somewhere nice.",
    "pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0",  # Z missing
    "pan: 75, tilt: 45, X: -1, Y: 0, Z: 0",  # zoom missing
    "pan: left, tilt: down, zoom: in, X: -1, Y: 0, Z: 0",
    "pan: nan, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0",
    "pan: inf, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0",
    "pan: 1" + "0" * 400 + ", tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0",  # overflows to inf
    "75, 45, 1, -1, 0, 0",  # no keys
    "fov: 90, resolution: 640, battery: 0.5, coverage: 0.2, altitude: 2, speed: 3",
    "position [x, y, z]: [3, 4, 1]; pan: 0, tilt: 90, zoom: 1.0",  # state, not advice
    '{"pan": null, "tilt": 45, "zoom": 1, "X": -1, "Y": 0, "Z": 0}',
]


@pytest.mark.parametrize(("text", "expected"), REAL_ANSWERS)
def test_real_answers(text: str, expected: Recommendation) -> None:
    assert parse_recommendation(text) == expected


@pytest.mark.parametrize("text", UNREADABLE)
def test_unreadable_gives_none(text: str) -> None:
    assert parse_recommendation(text) is None


@pytest.mark.parametrize("value", [None, 42, 1.5, b"pan: 75", ["pan: 75"], {"pan": 75}])
def test_non_text_gives_none(value: object) -> None:
    assert parse_recommendation(value) is None  # type: ignore[arg-type]


def test_result_values_are_in_range_and_typed() -> None:
    r = parse_recommendation("pan: 500, tilt: -3, zoom: 9.9, X: 7, Y: -7, Z: 0.2")
    assert r == rec(90.0, 0.0, 2.0, 1, -1, 0)
    assert isinstance(r.pan, float) and isinstance(r.dx, int)


# ------------------------------------------------------------------------------------------
# Property tests
# ------------------------------------------------------------------------------------------

FIELDS = ("pan", "tilt", "zoom", "dx", "dy", "dz")
KEY_NAMES = {
    "pan": ["pan", "Pan", "PAN", "camera_pan", "pan angle"],
    "tilt": ["tilt", "Tilt", "TILT", "camera_tilt", "tilt angle"],
    "zoom": ["zoom", "Zoom", "ZOOM", "zoom level", "camera_zoom"],
    "dx": ["X", "x", "dx", "move_x", "delta_x", "Move X"],
    "dy": ["Y", "y", "dy", "move_y", "delta_y", "Move Y"],
    "dz": ["Z", "z", "dz", "move_z", "delta_z", "Move Z"],
}

recommendations = st.builds(
    Recommendation,
    pan=st.integers(-9000, 9000).map(lambda v: v / 100),
    tilt=st.integers(0, 9000).map(lambda v: v / 100),
    zoom=st.integers(50, 200).map(lambda v: v / 100),
    dx=st.sampled_from([-1, 0, 1]),
    dy=st.sampled_from([-1, 0, 1]),
    dz=st.sampled_from([-1, 0, 1]),
)

# Noise that cannot form a "key: number" pair: no digits, no separators.
noise = st.text(
    alphabet=st.characters(
        blacklist_categories=("Nd", "Cs"), blacklist_characters=":=|>-\n\uff1a\uff1d\u2192"
    ),
    max_size=80,
)


def _value_text(value: float, style: int) -> str:
    text = f"{value:g}" if style % 2 == 0 else f"{value:.2f}"
    return text + ("°" if style == 2 else "")


@st.composite
def rendered(draw) -> tuple[str, Recommendation]:
    """A recommendation written in a random but valid style, and the recommendation."""
    r = draw(recommendations)
    order = list(FIELDS) if draw(st.booleans()) else draw(st.permutations(FIELDS))
    style = draw(st.sampled_from(["plain", "equals", "json", "lines", "bullets", "bold"]))
    value_style = draw(st.integers(0, 3))
    names = {f: draw(st.sampled_from(KEY_NAMES[f])) for f in FIELDS}
    values = {f: getattr(r, f) for f in FIELDS}
    if style == "json":
        body = json.dumps({names[f]: values[f] for f in order})
        text = draw(st.sampled_from(["{}", "```json\n{}\n```", "Answer: {}"])).format(body)
    else:
        sep = {"plain": ": ", "equals": " = ", "lines": ": ", "bullets": ": ", "bold": ":** "}
        pre = {"plain": "", "equals": "", "lines": "", "bullets": "- ", "bold": "**"}
        join = {"plain": ", ", "equals": " ", "lines": "\n", "bullets": "\n", "bold": "\n"}
        text = join[style].join(
            f"{pre[style]}{names[f]}{sep[style]}{_value_text(values[f], value_style)}"
            for f in order
        )
    # The written text is what the parser sees: round the expectation like the text.
    expected = parse_recommendation(r.to_text())
    return text, expected if value_style % 2 == 0 else r


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=300))
@example("pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: ")
@example(":" * 200)
@example("pan:" * 100)
@example("x: 1e999, " * 6)
def test_never_raises_on_random_text(text: str) -> None:
    result = parse_recommendation(text)
    assert result is None or isinstance(result, Recommendation)


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet=st.characters(codec="utf-8"), max_size=200))
def test_never_raises_on_random_unicode(text: str) -> None:
    result = parse_recommendation(text)
    assert result is None or isinstance(result, Recommendation)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.sampled_from(
                ["pan", "tilt", "zoom", "X", "Y", "Z", "dx", ":", "=", ",", "-", ".", " ", "\n"]
            ),
            st.integers(-1000, 1000).map(str),
            st.floats(allow_nan=True, allow_infinity=True).map(str),
        ),
        max_size=60,
    ).map("".join)
)
def test_never_raises_on_near_misses(text: str) -> None:
    result = parse_recommendation(text)
    assert result is None or isinstance(result, Recommendation)
    if result is not None:
        assert -90 <= result.pan <= 90 and 0 <= result.tilt <= 90 and 0.5 <= result.zoom <= 2
        assert {result.dx, result.dy, result.dz} <= {-1, 0, 1}
        assert all(math.isfinite(v) for v in (result.pan, result.tilt, result.zoom))


@settings(max_examples=300, deadline=None)
@given(recommendations)
def test_to_text_round_trips(r: Recommendation) -> None:
    assert parse_recommendation(r.to_text()) == r


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rendered(), noise, noise)
def test_valid_answers_embedded_in_noise(case, before: str, after: str) -> None:
    text, expected = case
    assert parse_recommendation(f"{before}\n{text}\n{after}") == expected


@settings(max_examples=300, deadline=None)
@given(
    recommendations,
    st.lists(st.sampled_from(["upper", "lower", "spaces", "nospace", "equals", "degrees"])),
)
def test_mutated_answers_still_parse(r: Recommendation, mutations: list[str]) -> None:
    text = r.to_text()
    for m in mutations:
        if m == "upper":
            text = text.upper()
        elif m == "lower":
            text = text.lower()
        elif m == "spaces":
            text = text.replace(": ", " :   ").replace(", ", " ,  ")
        elif m == "nospace":
            text = text.replace(" ", "")
        elif m == "equals":
            text = text.replace(":", "=")
        elif m == "degrees":
            text = text.replace(", tilt", "°, tilt").replace(", zoom", "°, zoom")
    assert parse_recommendation(text) == r


@settings(max_examples=300, deadline=None)
@given(recommendations, st.data())
def test_damaged_answers_never_raise(r: Recommendation, data: st.DataObject) -> None:
    text = r.to_text()
    i = data.draw(st.integers(0, len(text)))
    j = data.draw(st.integers(i, len(text)))
    insert = data.draw(st.text(max_size=10))
    damaged = text[:i] + insert + text[j:]
    result = parse_recommendation(damaged)
    assert result is None or isinstance(result, Recommendation)


@settings(max_examples=100, deadline=None)
@given(recommendations, st.data())
def test_truncated_answers_give_none(r: Recommendation, data: st.DataObject) -> None:
    text = r.to_text()
    cut = data.draw(st.integers(0, text.rindex("Z:") + 1))
    assert parse_recommendation(text[:cut]) is None
