"""CachedAdvisor (SQLite, WAL) and the budget, with a deterministic in-process advisor."""

from __future__ import annotations

import hashlib
import json
import logging
import pickle
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from pirl.advice import (
    BUDGET_EXHAUSTED,
    Advisor,
    Answer,
    Budget,
    BudgetedAdvisor,
    CachedAdvisor,
    Recommendation,
    cache_key,
    parse_recommendation,
)


class HashAdvisor(Advisor):
    """Answers computed from the prompt's hash; prompts containing "fail" fail, "junk" is
    unparseable. Records every batch it is asked."""

    name = "hash"
    model = "sha256"
    label = "hash advisor"

    def __init__(self, setting: str = "a") -> None:
        self.setting = setting
        self.batches: list[list[str]] = []

    def settings_key(self) -> str:
        return self.setting

    def advise(self, prompts: list[str], views=None) -> list[Answer]:
        self.batches.append(list(prompts))
        answers = []
        for p in prompts:
            if "fail" in p:
                answers.append(Answer("", None, error="server on fire"))
                continue
            if "junk" in p:
                answers.append(Answer("no idea", None, prompt_tokens=5, completion_tokens=2))
                continue
            h = hashlib.sha256(p.encode()).digest()
            rec = Recommendation(
                pan=float(h[0] % 181 - 90), tilt=float(h[1] % 91), zoom=0.5 + (h[2] % 16) / 10,
                dx=h[3] % 3 - 1, dy=h[4] % 3 - 1, dz=h[5] % 3 - 1,
            )  # fmt: skip
            answers.append(Answer(rec.to_text(), rec, 0.01, 10, 20))
        return answers


def test_hits_misses_and_one_inner_batch(tmp_path: Path) -> None:
    inner = HashAdvisor()
    cached = CachedAdvisor(inner, tmp_path / "c.sqlite")
    first = cached.advise(["p1", "p2", "p1", "p3"])
    assert inner.batches == [["p1", "p2", "p3"]]  # duplicates asked once
    assert (cached.hits, cached.misses) == (0, 4)
    assert not any(a.from_cache for a in first)
    second = cached.advise(["p3", "p4", "p1"])
    assert inner.batches[-1] == ["p4"]  # only the miss goes to the inner advisor
    assert (cached.hits, cached.misses) == (2, 5)
    assert [a.from_cache for a in second] == [True, False, True]
    assert second[0].text == first[3].text and second[0].recommendation == first[3].recommendation
    assert second[2].recommendation == first[0].recommendation
    assert second[0].prompt_tokens == 0  # a hit costs nothing
    assert cached.stats() == {"hits": 2, "misses": 5, "hit_rate": 2 / 7}
    assert len(cached) == 4
    assert cached.advise([]) == []


def test_failed_and_unparseable_answers_are_never_cached(tmp_path: Path) -> None:
    inner = HashAdvisor()
    cached = CachedAdvisor(inner, tmp_path / "c.sqlite")
    a = cached.advise(["fail 1", "junk 1", "ok"])
    assert a[0].error == "server on fire" and a[1].recommendation is None and a[2].ok
    b = cached.advise(["fail 1", "junk 1", "ok"])
    assert inner.batches[-1] == ["fail 1", "junk 1"]  # both asked again
    assert [x.from_cache for x in b] == [False, False, True]
    assert b[1].text == "no idea" and b[1].recommendation is None


def test_key_covers_advisor_model_settings_and_prompt(tmp_path: Path) -> None:
    path = tmp_path / "c.sqlite"
    CachedAdvisor(HashAdvisor("a"), path).advise(["p"])
    other_settings = CachedAdvisor(HashAdvisor("b"), path)
    other_settings.advise(["p"])
    assert other_settings.misses == 1
    same = CachedAdvisor(HashAdvisor("a"), path)
    same.advise(["p"])
    assert same.hits == 1
    keys = {
        cache_key("hash", "sha256", "a", "p"),
        cache_key("hash", "sha256", "b", "p"),
        cache_key("hash", "other", "a", "p"),
        cache_key("other", "sha256", "a", "p"),
        cache_key("hash", "sha256", "a", "p "),
    }
    assert len(keys) == 5 and all(len(k) == 64 for k in keys)


def test_persistent_wal_database(tmp_path: Path) -> None:
    path = tmp_path / "deep" / "folder" / "c.sqlite"
    cached = CachedAdvisor(HashAdvisor(), path)
    cached.advise(["p1", "p2"])
    cached.close()
    with sqlite3.connect(path) as conn:
        assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        rows = conn.execute("SELECT advisor, model, settings, prompt, text FROM answers").fetchall()
    assert {r[3] for r in rows} == {"p1", "p2"}
    assert all(r[:3] == ("hash", "sha256", "a") for r in rows)
    assert all(parse_recommendation(r[4]) is not None for r in rows)
    reopened = CachedAdvisor(HashAdvisor(), path)
    assert all(a.from_cache for a in reopened.advise(["p2", "p1"]))


def test_pickles_without_its_connection(tmp_path: Path) -> None:
    cached = CachedAdvisor(HashAdvisor(), tmp_path / "c.sqlite")
    cached.advise(["p1"])
    clone = pickle.loads(pickle.dumps(cached))
    assert clone.advise(["p1"])[0].from_cache


def test_broken_inner_advisor_does_not_raise(tmp_path: Path) -> None:
    class Broken(HashAdvisor):
        def advise(self, prompts, views=None):
            raise RuntimeError("bug")

    cached = CachedAdvisor(Broken(), tmp_path / "c.sqlite")
    answers = cached.advise(["p"])
    assert answers[0].error == "RuntimeError: bug"
    assert len(cached) == 0


WRITER = textwrap.dedent(
    """
    import hashlib, json, sys
    from pirl.advice import Advisor, Answer, CachedAdvisor, Recommendation

    class HashAdvisor(Advisor):
        name, model, label = "hash", "sha256", "hash advisor"
        def settings_key(self):
            return "a"
        def advise(self, prompts, views=None):
            out = []
            for p in prompts:
                h = hashlib.sha256(p.encode()).digest()
                rec = Recommendation(pan=float(h[0] % 90), tilt=float(h[1] % 90), zoom=1.0,
                                     dx=h[3] % 3 - 1, dy=0, dz=0)
                out.append(Answer(rec.to_text(), rec))
            return out

    worker, path = int(sys.argv[1]), sys.argv[2]
    cached = CachedAdvisor(HashAdvisor(), path, timeout_s=60)
    texts = {}
    for batch in range(20):
        # Overlapping prompt sets: every prompt is written by two workers.
        prompts = [f"prompt {(worker * 100 + batch * 10 + i) % 400}" for i in range(10)]
        for p, a in zip(prompts, cached.advise(prompts)):
            assert a.error is None and a.recommendation is not None
            texts[p] = a.text
    print(json.dumps({"hits": cached.hits, "misses": cached.misses, "texts": texts}))
    """
)


def test_several_processes_write_concurrently(tmp_path: Path) -> None:
    path = tmp_path / "shared.sqlite"
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", WRITER, str(w), str(path)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for w in range(4)
    ]
    results = []
    for p in procs:
        out, err = p.communicate(timeout=180)
        assert p.returncode == 0, err
        results.append(json.loads(out))
    assert all(r["hits"] + r["misses"] == 200 for r in results)
    merged: dict[str, str] = {}
    for r in results:
        for prompt, text in r["texts"].items():
            assert merged.setdefault(prompt, text) == text  # every process saw the same answer
    with sqlite3.connect(path) as conn:
        rows = dict(conn.execute("SELECT prompt, text FROM answers").fetchall())
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert rows == merged and len(rows) == 400


# ------------------------------------------------------------------------------------------
# Budget
# ------------------------------------------------------------------------------------------


def test_call_budget_stops_cleanly_with_one_warning(caplog) -> None:
    inner = HashAdvisor()
    budget = Budget(max_calls=5)
    adv = BudgetedAdvisor(inner, budget)
    caplog.set_level(logging.WARNING, logger="pirl.advice.budget")
    first = adv.advise(["a", "b", "c"])
    assert all(a.ok for a in first) and not adv.exhausted
    second = adv.advise(["d", "e", "f", "g"])
    assert [a.ok for a in second] == [True, True, False, False]
    assert second[2].error == BUDGET_EXHAUSTED and second[2].recommendation is None
    assert adv.exhausted and budget.exhausted and budget.remaining_calls == 0
    third = adv.advise(["h", "i"])
    assert all(a.error == BUDGET_EXHAUSTED for a in third)
    assert inner.batches == [["a", "b", "c"], ["d", "e"]]  # never called once spent
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "budget exhausted" in warnings[0].getMessage()
    assert (adv.calls, adv.tokens) == (5, 150)


def test_token_budget() -> None:
    inner = HashAdvisor()
    adv = BudgetedAdvisor(inner, Budget(max_tokens=70))
    assert all(a.ok for a in adv.advise(["a", "b"]))  # 60 tokens
    assert not adv.exhausted
    assert all(a.ok for a in adv.advise(["c", "d"]))  # crosses the limit: completes
    assert adv.exhausted
    assert adv.advise(["e"])[0].error == BUDGET_EXHAUSTED
    assert len(inner.batches) == 2
    assert adv.budget.as_dict() == {
        "max_calls": None, "max_tokens": 70, "calls": 4, "tokens": 120, "exhausted": True,
    }  # fmt: skip


def test_no_limits_and_invalid_limits() -> None:
    adv = BudgetedAdvisor(HashAdvisor(), Budget())
    assert all(a.ok for a in adv.advise([f"p{i}" for i in range(50)]))
    assert not adv.exhausted and adv.budget.remaining_calls is None
    assert Budget(max_calls=0).exhausted
    with pytest.raises(ValueError):
        Budget(max_calls=-1)


def test_budget_behind_cache_charges_only_misses(tmp_path: Path) -> None:
    budget = Budget(max_calls=2)
    stack = CachedAdvisor(BudgetedAdvisor(HashAdvisor(), budget), tmp_path / "c.sqlite")
    assert all(a.ok for a in stack.advise(["a", "b"]))
    assert stack.exhausted and stack.calls == 2
    again = stack.advise(["a", "b", "c"])
    assert [a.ok for a in again] == [True, True, False]  # hits still served
    assert again[2].error == BUDGET_EXHAUSTED
    assert len(stack) == 2  # the refusal was not cached
    assert stack.name == "hash" and stack.label == "hash advisor"
