"""build_prompt: every item of the paper's prompt, rounding, determinism, variants."""

from __future__ import annotations

import dataclasses
import math
import os

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pirl.advice import FORMAT_EXAMPLE, VARIANTS, PromptState, build_prompt, parse_recommendation
from pirl.advice.prompt import PROMPT_VERSION, STATE_MARKER, prompt_id
from pirl.config.grid import paper_half_width

STATE = PromptState(
    position=(14, 0, 2),
    tilt=60,
    pan=90,
    zoom=1.0,
    battery=0.24,
    coverage=0.7837,
    size=(15, 15, 3),
    obstacles=((5.0, 5.0, 1.0, 1.5), (10.04, 9.96, 2.0, 2.0)),
)


def test_paper_prompt_has_every_item() -> None:
    text = build_prompt(STATE)
    rest, env = text.split("[Environment]")
    task, request = rest.split("[Request]")
    assert "[Task]" in task and "ground" in task and "obstacles" in task and "battery" in task
    assert "[14, 0, 2]" in env  # position
    assert "[90, 640x480, 60, 90, 1.0]" in env  # [fov, resolution, tilt, pan, zoom]
    assert "Battery: 0.24" in env
    assert "Coverage: 0.78" in env
    assert "15 x 15 x 3" in env
    assert "floor(m*zoom+0.5)" in env and "tilt < 80" in env and "5x5 cells" in env
    assert "[5.0, 5.0, 1.0] radius 1.5" in env
    assert "[10.0, 10.0, 2.0] radius 2.0" in env
    for item in ("pan [-90, 90]", "tilt [0, 90]", "zoom [0.5, 2.0]", "-1, 0 or 1"):
        assert item in request
    assert request.rstrip().endswith(FORMAT_EXAMPLE)
    # The order is task || request || environment: the state comes last.
    assert text.index("[Task]") < text.index("[Request]") < text.index("[Environment]")


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("footprint", ["paper", "frustum"])
def test_the_state_comes_last_after_a_shared_prefix(variant: str, footprint: str) -> None:
    # Two different states of one world configuration share everything up to the state: the
    # task, the reply format, the view rule and the grid (local.py reuses its key/value cache).
    a = dataclasses.replace(STATE, footprint=footprint)
    b = dataclasses.replace(
        a, position=(3, 7, 0), tilt=90, pan=-45, zoom=2.0, battery=0.9, coverage=0.1,
        obstacles=((1.0, 2.0, 0.0, 1.0),),
    )  # fmt: skip
    ta, tb = build_prompt(a, variant), build_prompt(b, variant)
    shared = len(os.path.commonprefix([ta, tb]))
    marker = STATE_MARKER
    assert shared >= ta.index(marker) and shared > 0.45 * len(ta)
    head = ta[: ta.index(marker)]
    for item in ("format", "floor(m*zoom" if footprint == "paper" else "2*atan", "15"):
        assert item in head
    assert "[14" not in head and "0.24" not in head  # no state before the marker


def test_prompt_id_carries_the_text_version() -> None:
    assert prompt_id("compact") == f"compact-v{PROMPT_VERSION}" and PROMPT_VERSION >= 2


def test_compact_prompt_has_every_item() -> None:
    text = build_prompt(STATE, "compact")
    for item in (
        "[14,0,2]",
        "[90,640x480,60,90,1.0]",
        "Battery 0.24",
        "coverage 0.78",
        "15x15x3",
        "floor(m*zoom+0.5)",
        "[5.0,5.0,1.0,1.5]",
        "[10.0,10.0,2.0,2.0]",
        "pan: <-90..90>, tilt: <0..90>, zoom: <0.5..2.0>, X: <-1|0|1>, Y: <-1|0|1>, Z: <-1|0|1>",
    ):
        assert item in text
    assert len(text) < 0.75 * len(build_prompt(STATE))


def test_frustum_view_cone() -> None:
    state = dataclasses.replace(STATE, footprint="frustum", zoom=2.0, position=(3, 4, 1))
    for variant in VARIANTS:
        text = build_prompt(state, variant)
        assert "pinhole" in text
        assert "2 cells" in text  # altitude z + 1
        assert "2*atan(tan(90/2)/zoom)" in text
        fov = math.degrees(2 * math.atan(1 / 2.0))
        assert f"{fov:.0f}" in text  # 53 degrees at zoom 2
        assert "8.0 cells" in text  # max range
        assert "floor(m*zoom" not in text


@pytest.mark.parametrize(
    ("tilt", "zoom", "half"),
    [(90, 1.0, 1), (80, 1.0, 1), (79, 1.0, 2), (60, 2.0, 4), (90, 2.0, 2), (90, 0.5, 1),
     (60, 0.5, 1), (60, 0.7, 1), (60, 0.8, 2), (90, 1.4, 1), (90, 1.5, 2)],
)  # fmt: skip
def test_paper_half_width(tilt: int, zoom: float, half: int) -> None:
    assert paper_half_width(tilt, round(zoom * 10)) == half
    side = 2 * half + 1
    state = dataclasses.replace(STATE, tilt=tilt, zoom=zoom)
    assert f"{side}x{side} cells" in build_prompt(state)


def test_rounding_makes_equal_situations_equal() -> None:
    a = dataclasses.replace(STATE, battery=0.24001, coverage=0.78370001)
    b = dataclasses.replace(STATE, battery=0.23999, coverage=0.7837, zoom=1.0000000001)
    c = dataclasses.replace(STATE, obstacles=((5.04, 4.96, 1.0, 1.5), (10.0, 10.0, 2.0, 2.0)))
    for variant in VARIANTS:
        assert build_prompt(a, variant) == build_prompt(b, variant) == build_prompt(c, variant)
        assert build_prompt(STATE, variant) == build_prompt(STATE, variant)


def test_decimals() -> None:
    assert "Battery: 0.240" in build_prompt(STATE, decimals=3)
    assert "Coverage: 0.784" in build_prompt(STATE, decimals=3)
    assert "Battery: 0 " in build_prompt(STATE, decimals=0)
    with pytest.raises(ValueError):
        build_prompt(STATE, decimals=-1)


def test_no_negative_zero_and_clamped_fractions() -> None:
    state = dataclasses.replace(
        STATE, battery=-0.0001, coverage=1.2, obstacles=((-0.01, 0.0, 0.0, 1.0),)
    )
    text = build_prompt(state)
    assert "-0.0" not in text
    assert "Battery: 0.00" in text and "Coverage: 1.00" in text


def test_no_obstacles() -> None:
    state = dataclasses.replace(STATE, obstacles=())
    assert "none" in build_prompt(state)
    assert "Obstacles [x,y,z,radius]: none" in build_prompt(state, "compact")


def test_unknown_variant_names_the_allowed_ones() -> None:
    with pytest.raises(ValueError, match="paper.*compact"):
        build_prompt(STATE, "fancy")


def test_invalid_states() -> None:
    with pytest.raises(ValueError, match="footprint"):
        dataclasses.replace(STATE, footprint="cone")
    with pytest.raises(ValueError):
        dataclasses.replace(STATE, size=(0, 15, 3))
    with pytest.raises(ValueError):
        dataclasses.replace(STATE, obstacles=((1.0, 2.0, 3.0),))
    with pytest.raises(ValueError):
        dataclasses.replace(STATE, battery=float("nan"))


def test_example_in_prompt_parses_to_the_paper_sample() -> None:
    r = parse_recommendation(FORMAT_EXAMPLE)
    assert (r.pan, r.tilt, r.zoom, r.dx, r.dy, r.dz) == (75, 45, 1.0, -1, 0, 0)


states = st.builds(
    PromptState,
    position=st.tuples(st.integers(0, 59), st.integers(0, 59), st.integers(0, 2)),
    tilt=st.integers(0, 18).map(lambda v: 5 * v),
    pan=st.integers(-6, 6).map(lambda v: 15 * v),
    zoom=st.integers(5, 20).map(lambda v: v / 10),
    battery=st.floats(0, 1),
    coverage=st.floats(0, 1),
    size=st.sampled_from([(15, 15, 3), (30, 30, 3), (60, 60, 3)]),
    footprint=st.sampled_from(["paper", "frustum"]),
    obstacles=st.lists(
        st.tuples(*[st.floats(0, 60, allow_nan=False)] * 3, st.floats(1, 2)), max_size=5
    ).map(tuple),
)


@settings(max_examples=100, deadline=None)
@given(states, st.sampled_from(VARIANTS))
def test_prompts_are_deterministic_and_short(state: PromptState, variant: str) -> None:
    text = build_prompt(state, variant)
    assert text == build_prompt(dataclasses.replace(state), variant)
    assert "nan" not in text and "-0.0" not in text
    limit = 1800 if variant == "paper" else 1050  # characters, with five obstacles
    assert len(text) < limit
