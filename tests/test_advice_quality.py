"""How good must the LLM be: the degradable oracle, ``pirl advise --score``, your
own prompt as a template, and the student's gate on what it learned of the teacher's signal.
Real advisors throughout: the oracle, the embedded LLM, an OpenAI-compatible server on
loopback (the plugin advisor is scored in tests/test_plugins.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from chat_server import ChatServer
from pirl.advice.oracle import MOVES, OracleAdvisor, degraded, oracle_label
from pirl.advice.prompt import PromptState, build_prompt, prompt_id
from pirl.advice.recommendation import Recommendation
from pirl.advice.student import Student, StudentScore, gate_value
from pirl.config.errors import ConfigError
from pirl.config.run import RunConfig

ROOT = Path(__file__).resolve().parents[1]
TEST_CFG = ROOT / "configs" / "test.yaml"
PIRL = [sys.executable, "-m", "pirl"]
GOOD = "pan: 15, tilt: 45, zoom: 1.0, X: 1, Y: 0, Z: 0"
REC = Recommendation(pan=0, tilt=90, zoom=1.0, dx=1, dy=0, dz=0)


def _pirl(*args: str, cwd: Path, env: dict | None = None, timeout: float = 600):
    env = {**os.environ, "COLUMNS": "200", **(env or {})}
    return subprocess.run(
        [*PIRL, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env
    )


# -- 1. the degradable oracle ------------------------------------------------------------------
def test_a_degraded_oracle_keeps_its_answer_on_the_accuracy_share_of_states():
    prompts = [f"state {k}" for k in range(4000)]
    for accuracy in (0.0, 0.25, 0.5, 0.75, 1.0):
        kept = np.mean([degraded(REC, p, accuracy) == REC for p in prompts])
        # A replacement equals the oracle's answer by chance only (1 in 7 moves x cameras).
        assert abs(kept - accuracy) < 0.03, (accuracy, kept)
    # One state, one answer, whatever the call.
    assert degraded(REC, "same", 0.5) == degraded(REC, "same", 0.5)
    answers = {degraded(REC, p, 0.0).move for p in prompts[:500]}
    assert answers == set(MOVES)


def test_the_degraded_oracle_says_so_everywhere():
    assert OracleAdvisor().label == oracle_label(1.0) == "oracle (not an LLM)"
    half = OracleAdvisor(0.5)
    assert half.label == "oracle, accuracy 0.5 (not an LLM)"
    assert half.settings_key() != OracleAdvisor().settings_key()
    cfg = RunConfig.from_yaml(TEST_CFG).with_variant({"advisor": "oracle", "oracle_accuracy": 0.5})
    assert cfg.advisor.oracle_accuracy == 0.5 and cfg.pare.advisor == "oracle"
    with pytest.raises(ConfigError, match="advisor.oracle_accuracy"):
        RunConfig.from_dict({"advisor": {"oracle_accuracy": 1.5}})
    with pytest.raises(ConfigError, match="unknown setting 'lam_camm'"):
        cfg.with_variant({"lam_camm": 1})


# -- 2. pirl advise --score --------------------------------------------------------------------
def test_score_of_the_oracle_and_the_degraded_oracle(tmp_path):
    from pirl.evaluate.advice_score import score_advisor

    cfg = RunConfig.from_yaml(TEST_CFG)
    perfect = score_advisor(OracleAdvisor(), cfg, 200)
    assert perfect.states == 200 and perfect.parse_rate == 1.0
    assert perfect.agreement_move == perfect.agreement_position == perfect.agreement_camera == 1
    assert perfect.alignment_mean == pytest.approx(perfect.alignment_oracle)
    half = score_advisor(OracleAdvisor(0.5), cfg, 400)
    implied = 0.5 + 0.5 / len(MOVES)  # kept, or replaced by the same move by chance
    assert abs(half.agreement_move - implied) < 0.05, half.agreement_move
    assert 0 < half.kappa_move < perfect.kappa_move
    assert half.alignment_mean < perfect.alignment_mean


def test_pirl_advise_score_prints_and_writes_the_score_and_the_price(tmp_path):
    out = tmp_path / "score.json"
    proc = _pirl(
        "advise", "--advisor", "oracle", "--config", str(TEST_CFG), "--score", "60",
        "--out", str(out), "--price-in", "0.5", "--price-out", "1.5", cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "agreement: move" in proc.stdout and "price of one PIRL run of quick" in proc.stdout
    score = json.loads(out.read_text())
    keys = {"parse_rate", "agreement_move", "agreement_position", "agreement_camera",
            "kappa_move", "alignment_mean", "latency_p50_s", "latency_p95_s", "tokens_in",
            "tokens_out", "price"}  # fmt: skip
    assert keys <= set(score)
    assert score["agreement_move"] == 1.0 and score["price"]["calls"] > 0
    assert score["price"]["cost"] > 0
    bad = _pirl("advise", "--advisor", "oracle", "--score", "0", cwd=tmp_path)
    assert bad.returncode == 2 and "--score 0" in bad.stderr


def test_the_embedded_llm_is_scored_and_priced(tmp_path):
    proc = _pirl("advise", "--score", "6", "--out", str(tmp_path / "s.json"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    score = json.loads((tmp_path / "s.json").read_text())
    assert score["states"] == 6 and score["prompt_variant"] == "compact"
    assert score["tokens_in"] > 0 and score["price"]["calls"] > 0


def test_an_openai_compatible_server_is_scored_with_its_own_token_counts(tmp_path):
    usage = {"prompt_tokens": 120, "completion_tokens": 14, "total_tokens": 134}
    with ChatServer(GOOD, usage) as server:
        proc = _pirl(
            "advise", "--advisor", "openai", "--base-url", server.url, "--model", "m",
            "--config", str(TEST_CFG), "--score", "30", "--no-cache",
            "--out", str(tmp_path / "s.json"), cwd=tmp_path,
            env={"PIRL_CACHE_DIR": str(tmp_path / "cache")},
        )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    score = json.loads((tmp_path / "s.json").read_text())
    assert score["parse_rate"] == 1.0 and score["tokens_counted_by"] == "server"
    assert score["tokens_in"] == 120 and score["tokens_out"] == 14
    assert score["kappa_move"] == pytest.approx(0.0, abs=0.05)  # one answer for every state


# -- 3. your own prompt --------------------------------------------------------------------------
def _states(n: int) -> list[PromptState]:
    rng = np.random.default_rng(3)
    out = []
    for _ in range(n):
        size = (int(rng.integers(3, 40)), int(rng.integers(3, 40)), int(rng.integers(3, 6)))
        out.append(
            PromptState(
                position=tuple(int(rng.integers(0, s)) for s in size),
                tilt=int(rng.choice(range(0, 91, 5))), pan=int(rng.choice(range(-90, 91, 15))),
                zoom=float(rng.choice([0.5, 0.8, 1.0, 1.25, 2.0])), battery=float(rng.random()),
                coverage=float(rng.random()), size=size,
                footprint=str(rng.choice(["paper", "frustum"])),
                fov_deg=float(rng.choice([60.0, 90.0])),
                obstacles=tuple(
                    tuple(float(v) for v in rng.random(4) * 10) for _ in range(rng.integers(0, 4))
                ),
                teammates=tuple(  # a fleet's in every other state
                    (*(int(rng.integers(0, s)) for s in size), float(rng.random()))
                    for _ in range(int(rng.integers(0, 4)) * (len(out) % 2))
                ),
            )
        )  # fmt: skip
    return out


@pytest.mark.parametrize("variant", ["paper", "compact"])
def test_the_shipped_templates_are_the_built_in_prompts_byte_for_byte(variant):
    template = f"file:{ROOT / 'examples' / 'prompts' / f'{variant}.j2'}"
    for state in _states(200):
        for decimals in (2, 3):
            assert build_prompt(state, template, decimals) == build_prompt(state, variant, decimals)


def test_a_template_changes_the_prompt_and_the_keys(tmp_path):
    from pirl.advice.student import teacher_key

    mine = tmp_path / "mine.j2"
    mine.write_text(
        "Grid {{ sx }}x{{ sy }}; at {{ x }},{{ y }},{{ z }}. Reply: {{ format_ranges }}\n"
    )
    cfg = RunConfig.from_dict({"advisor": {"prompt_file": str(mine)}})
    assert cfg.pare.prompt_variant == f"file:{mine.resolve()}"
    state = _states(1)[0]
    text = build_prompt(state, cfg.pare.prompt_variant)
    assert text.startswith(f"Grid {state.size[0]}x") and not text.endswith("\n")
    assert prompt_id(cfg.pare.prompt_variant) != prompt_id("compact")
    adv = OracleAdvisor()
    before = teacher_key(adv, cfg.pare.prompt_variant, cfg.env)
    mine.write_text("Other {{ x }}. Reply: {{ format_ranges }}\n")
    os.utime(mine, ns=(1, 10**18))  # a new modification time: the template is read again
    assert teacher_key(adv, cfg.pare.prompt_variant, cfg.env) != before


def test_template_mistakes_are_one_line(tmp_path):
    with pytest.raises(ConfigError, match="advisor.prompt_file"):
        RunConfig.from_dict({"advisor": {"prompt_file": str(tmp_path / "none.j2")}})
    broken = tmp_path / "broken.j2"
    broken.write_text("{% if %}\n")
    cfg = RunConfig.from_dict({"advisor": {"prompt_file": str(broken)}})
    with pytest.raises(ConfigError, match="line 1"):
        build_prompt(_states(1)[0], cfg.pare.prompt_variant)
    unknown = tmp_path / "unknown.j2"
    unknown.write_text("{{ altitude_in_feet }}\n")
    cfg = RunConfig.from_dict({"advisor": {"prompt_file": str(unknown)}})
    with pytest.raises(ConfigError, match="altitude_in_feet"):
        build_prompt(_states(1)[0], cfg.pare.prompt_variant)
    proc = _pirl("advise", "--advisor", "oracle", "--config", str(_cfg(tmp_path, unknown)),
                 cwd=tmp_path)  # fmt: skip
    assert proc.returncode == 2 and "altitude_in_feet" in proc.stderr
    assert "Traceback" not in proc.stderr


def _cfg(tmp_path: Path, template: Path) -> Path:
    path = tmp_path / "cfg.yaml"
    path.write_text(f"advisor:\n  prompt_file: {template}\n")
    return path


def test_the_default_advise_command_of_the_default_advisor_passes(tmp_path):
    proc = _pirl("advise", cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Reply in this format: pan: <-90..90>" in proc.stdout  # the compact prompt


# -- 4. the gate -----------------------------------------------------------------------------
def _student_of(labels_of, n: int = 600):
    """A student fitted on ``n`` rows whose teacher answers ``labels_of(features)``."""
    from pirl.advice.student import Student

    rng = np.random.default_rng(0)
    x = rng.random((n, 8)).astype(np.float32)
    student = Student("t", 8, hidden=32, seed=0)
    student.add(np.arange(1, n + 1), x, labels_of(x, rng))
    student.fit(300)
    return student


def _labels(moves: np.ndarray) -> np.ndarray:
    y = np.zeros((len(moves), 6), dtype=np.int64)
    y[:, 0], y[:, 1], y[:, 2] = 6, 18, 5  # a fixed camera (pan 0, tilt 90, zoom 1.0)
    y[:, 3] = moves  # dx class: 0, 1 or 2 for -1, 0, 1
    y[:, 4] = y[:, 5] = 1
    return y


def test_the_kappa_gate_lets_a_noisy_teacher_in_and_keeps_a_constant_one_out():
    signal = lambda x, rng: _labels((x[:, 0] * 3).astype(int).clip(0, 2))  # noqa: E731

    def noisy(x, rng):
        y = signal(x, rng)
        flip = rng.random(len(y)) < 0.25
        y[flip, 3] = rng.integers(0, 3, flip.sum())
        return y

    constant = lambda x, rng: _labels(np.ones(len(x), dtype=int))  # noqa: E731
    informed, constant_student = _student_of(noisy), _student_of(constant)
    # The noisy teacher's student: agreement below the old 0.8 gate, yet kappa well above 0.
    assert informed.score.agreement < 0.95 and informed.score.kappa > 0.3
    assert informed.score.informative == ("dx",)
    assert informed.passes(0.1, "kappa")
    # The constant teacher: high agreement (the old gate passed it), no information.
    assert constant_student.score.agreement == 1.0 and constant_student.passes(0.8, "agreement")
    assert constant_student.score.informative == () and constant_student.score.kappa == 0.0
    assert not constant_student.passes(0.1, "kappa")
    # The lower bound: the informed student's kappa less three standard errors, still above 0;
    # the constant teacher's student has nothing to bound.
    se = informed.score.kappa_se
    assert 0 < se < 0.1
    assert gate_value(informed.score, "kappa_lcb") == pytest.approx(informed.score.kappa - 3 * se)
    assert informed.passes(0.02, "kappa_lcb") and not constant_student.passes(0.0, "kappa_lcb")


def test_the_gate_waits_for_pare_student_min_heldout_answers():
    from pirl.agents.pirl_advice import unshaped_warning
    from pirl.config.errors import ConfigError

    student = _student_of(lambda x, rng: _labels(np.ones(len(x), dtype=int)))
    held = student.score.heldout
    assert held >= 20 and student.passes(0.8, "agreement")  # the default minimum, 20
    student.min_heldout = held + 1  # one more held-out answer than it has
    assert not student.passes(0.8, "agreement")
    stats = {"steps": 1000, "steps_unshaped": 1000, "mode": "student", "student_heldout": 7,
             "student_informative": ["dx"], "gate_passed_at_step": -1}  # fmt: skip
    assert "on 7 held-out answers; it needs 5)" in unshaped_warning(stats, 0.5, 0.1, 5)
    with pytest.raises(ConfigError, match="pare.student_min_heldout=0: must be > 0"):
        RunConfig.from_dict({"pare": {"student_min_heldout": 0}})


def test_kappa_error_is_cohens_large_sample_error():
    from pirl.advice.student import cohen_kappa, kappa_error

    truth = np.array([0, 0, 1, 1, 2, 2, 0, 1, 2, 0])
    pred = np.array([0, 0, 1, 2, 2, 2, 1, 1, 2, 0])
    observed, n = 0.8, 10
    chance = (np.bincount(pred, minlength=3) / n) @ (np.bincount(truth, minlength=3) / n)
    assert cohen_kappa(pred, truth, 3) == pytest.approx((observed - chance) / (1 - chance))
    assert kappa_error(pred, truth, 3) == pytest.approx(
        np.sqrt(observed * (1 - observed) / n) / (1 - chance)
    )
    assert kappa_error(pred[:0], truth[:0], 3) == 1.0


def test_the_unshaped_warning_says_when_a_teacher_carries_no_information():
    from pirl.agents.pirl_advice import unshaped_warning

    stats = {"steps": 1000, "steps_unshaped": 1000, "mode": "student", "student_kappa": 0.0,
             "student_informative": [], "student_heldout": 50}  # fmt: skip
    line = unshaped_warning(stats, 0.5, 0.1)
    assert line is not None and "carry no state information" in line


# -- 5. the curve ------------------------------------------------------------------------------
def test_the_curve_has_measured_points_a_band_and_a_break_even(tmp_path):
    from pirl.report.advice_curve import CurveAdvisor, break_even, curve_points, plot, section

    rng = np.random.default_rng(0)
    records = []

    def runs(name: str, vcr: float) -> frozenset[str]:
        sources = []
        for seed in range(3):
            source = f"{name}-s{seed}"
            sources.append(source)
            for _ in range(4):
                records.append({"source": source, "train_seed": seed, "size": "30x30x3",
                                "act": "stochastic", "sim": "grid",
                                "vcr": vcr + 0.01 * rng.standard_normal()})  # fmt: skip
        return frozenset(sources)

    base = runs("ppo-ewri", 0.85)
    good = CurveAdvisor("oracle (not an LLM)", 1.0, 1.0, runs("good", 0.99), 0.98)
    weak = CurveAdvisor("oracle, accuracy 0.25 (not an LLM)", 0.36, 0.2, runs("weak", 0.85), 0.0)
    points, band = curve_points(records, [good, weak], base, "stochastic")
    assert {p.advisor.label for p in points} == {good.label, weak.label}
    found = break_even(points, "30x30x3")
    assert found is not None and found.advisor is good and found.p_lo > 0.5
    table = section(points, band, "stochastic")
    assert any(line.startswith("30x30x3: break-even at agreement 1.00") for line in table.bullets)
    assert table.rows[-1][:4] == ["PPO-EWRI", "-", "-", "30x30x3"]
    assert "0%" in [row[2] for row in table.rows]  # the weak advisor shaped none of its runs
    assert plot(points, band, tmp_path / "a.png", "stochastic").stat().st_size > 1000


def test_an_open_gate_closes_only_below_its_hysteresis():
    student = Student("t", 4)
    student.score = StudentScore(0.5, 0.4, 60, {}, kappa=0.07)
    # kappa 0.07: a closed gate at 0.1 stays closed; an open one (closing below 0.05) stays open
    assert not student.gate_after_fit(False, 0.1, 0.05, "kappa")
    assert student.gate_after_fit(True, 0.1, 0.05, "kappa")
    student.score = StudentScore(0.5, 0.4, 60, {}, kappa=0.03)
    assert not student.gate_after_fit(True, 0.1, 0.05, "kappa")
    student.score = StudentScore(0.5, 0.4, 60, {}, kappa=0.12)
    assert student.gate_after_fit(False, 0.1, 0.05, "kappa")
    student.score = StudentScore(0.5, 0.4, 5, {}, kappa=0.5)  # too few held-out answers
    assert not student.gate_after_fit(True, 0.1, 0.05, "kappa")
    cfg = RunConfig().pare
    assert cfg.gate_close() == pytest.approx(cfg.student_kappa_gate * cfg.student_gate_close)


def test_the_price_counts_the_calls_of_a_closed_gate():
    from pirl.evaluate.advice_score import price_run, run_calls

    cfg = RunConfig.from_yaml(ROOT / "configs" / "quick.yaml")
    head = cfg.reproduce.teacher_phase_answers
    plain = cfg.with_overrides(pare={"student_closed_rate": 1.0})
    base = run_calls(plain, "local") - head
    boosted = cfg.with_overrides(pare={"student_closed_rate": 3.0})
    assert base > 0 and run_calls(boosted, "local") - head == pytest.approx(3 * base, abs=3)
    assert run_calls(boosted, "local", gate_open=True) == run_calls(plain, "local")
    price = price_run(boosted, "local", "quick", 400.0, 20.0)
    assert f"{base + head:,} to {run_calls(boosted, 'local'):,} LLM calls" in price.line()
    assert "to" not in price_run(plain, "local", "quick", 400.0, 20.0).line().split(":")[1][:20]
