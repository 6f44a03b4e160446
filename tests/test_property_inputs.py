"""What users type, generated: YAML documents fed to the config loader, option
values fed to the command line's parsing. Each ends in a config, or in one ConfigError /
UserError line (exit 2 on the command line); never in another exception or a traceback."""

from __future__ import annotations

import dataclasses
import math
import tempfile
from pathlib import Path

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from pirl.cli import app
from pirl.config.errors import ConfigError
from pirl.config.load import check_seed, read_yaml
from pirl.config.run import RunConfig
from pirl.evaluate.scenarios import parse_size

SECTIONS = {f.name: f.type for f in dataclasses.fields(RunConfig)}
FIELDS = {
    f.name: [g.name for g in dataclasses.fields(getattr(RunConfig(), f.name))]
    for f in dataclasses.fields(RunConfig)
}
FAST = settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow], database=None
)

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**40), 2**40),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
)
values = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=3)
    ),
    max_leaves=8,
)


@st.composite
def documents(draw) -> object:
    """Mostly run configs with real section and key names (so value checks are reached),
    sometimes unknown names, sometimes not a mapping at all."""
    if draw(st.integers(0, 9)) == 0:
        return draw(values)
    doc: dict[str, object] = {}
    for section in draw(st.lists(st.sampled_from(sorted(SECTIONS)), max_size=3, unique=True)):
        keys = FIELDS[section] + ["bogus_key"]
        chosen = draw(st.lists(st.sampled_from(keys), max_size=3, unique=True))
        doc[section] = {key: draw(values) for key in chosen}
    if draw(st.booleans()):
        doc[draw(st.text(max_size=6))] = draw(values)
    return doc


def _load(text: str) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "c.yaml"
        path.write_text(text, encoding="utf-8")
        try:
            cfg = RunConfig.from_yaml(path)
        except ConfigError as exc:
            assert "\n" not in str(exc).strip(), str(exc)
        else:
            assert isinstance(cfg, RunConfig)


@FAST
@given(documents())
def test_generated_config_documents_give_a_config_or_one_line(doc):
    _load(yaml.safe_dump(doc, allow_unicode=True))


@FAST
@given(st.text(max_size=80))
def test_any_text_as_a_config_file_gives_a_config_or_one_line(text):
    _load(text)


@FAST
@given(st.text(max_size=20) | st.integers(-5, 10**6).map(str))
def test_size_texts_parse_or_give_one_line(text):
    try:
        size = parse_size(text)
    except ConfigError as exc:
        assert "\n" not in str(exc)
    else:
        assert len(size) == 3 and min(size) >= 3


@FAST
@given(st.integers(-(2**70), 2**70))
def test_seeds_are_checked_in_one_line(seed):
    try:
        assert check_seed(seed) == seed and 0 <= seed < 2**32
    except ConfigError as exc:
        assert "--seed" in str(exc) and not 0 <= seed < 2**32


def test_read_yaml_refuses_python_tags(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("env: !!python/object/apply:os.system ['true']\n")
    try:
        read_yaml(path)
    except ConfigError as exc:
        assert "\n" not in str(exc)
    else:  # pragma: no cover - the safe loader must refuse the tag
        raise AssertionError("a python tag was accepted")


sides = st.integers(-3, 9) | st.sampled_from([2049, 10**6])
option_text = st.text(alphabet="-0123456789xab.", min_size=1, max_size=6)


@settings(max_examples=25, deadline=None, database=None)
@given(
    size=st.tuples(sides | option_text, sides | option_text, st.integers(-1, 4) | option_text),
    seed=st.integers(-(2**33), 2**33) | option_text,
    fps=st.integers(-2, 30) | option_text,
)
def test_render_options_give_a_gif_or_one_line(size, seed, fps):
    runner = CliRunner()
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "e.gif"
        args = ["render", "--size", *map(str, size), "--seed", str(seed), "--fps", str(fps)]
        result = runner.invoke(app, [*args, "--out", str(out)])
        assert result.exit_code in (0, 2), (args, result.output, result.exception)
        assert result.exception is None or isinstance(result.exception, SystemExit), (
            args,
            result.exception,
        )
        assert "Traceback" not in result.output
        if result.exit_code == 0:
            assert out.is_file()
        else:
            assert not out.exists()
            assert not any(Path(folder).iterdir())


def test_finite_floats_only_where_finite_is_needed():
    # A NaN in a numeric setting is refused, not carried into training.
    try:
        RunConfig.from_dict({"ppo": {"learning_rate": math.nan}})
    except ConfigError:
        pass
    else:  # pragma: no cover
        raise AssertionError("ppo.learning_rate=nan was accepted")
