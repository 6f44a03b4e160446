"""The embedded advisor: a transformers causal LM on CPU (or CUDA), batched, format-constrained.

The model comes from :mod:`pirl.advice.model_store` (the embedded SmolLM2-135M-Instruct by
default); with ``constrained=True`` (default) the answer is prefilled with ``pan:`` and decoded
under the answer grammar of :mod:`pirl.advice.grammar` (by :mod:`pirl.advice.decoding`), so
every answer parses. The prompts' shared part (everything before the state marker) is run
once: its key/value cache is kept and decoding starts from it for every batch that shares it.
"""

from __future__ import annotations

import copy
import json
import os
import time
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

from pirl.advice.base import Advisor, Answer, error_answer
from pirl.advice.decoding import cache_of, grammar_decode
from pirl.advice.grammar import PREFILL, Grammar
from pirl.advice.model_store import default_dtype, load_model, resolve_model_dir
from pirl.advice.parser import parse_recommendation
from pirl.advice.prompt import STATE_MARKER

if TYPE_CHECKING:  # pragma: no cover
    import torch

__all__ = ["MAX_PREFIXES", "MIN_PREFIX", "LocalAdvisor"]

MIN_PREFIX = 16
"""Fewest shared tokens worth keeping a prefix cache for."""
MAX_PREFIXES = 8
"""Prefix caches kept (one per world configuration and prompt variant in use)."""


class LocalAdvisor(Advisor):
    """A transformers causal LM answering prompts in batches, on CPU or CUDA.

    Args:
        model: ``None`` for the embedded SmolLM2-135M-Instruct (converted once into the cache),
            or a Hugging Face model folder, or a ``.gguf`` file.
        cache_dir: cache root for converted models (default:
            :func:`pirl._paths.cache_root`).
        device: ``"cpu"``, ``"cuda"``, ... (default: CUDA when available, else CPU).
        dtype: torch dtype name (default: :func:`~pirl.advice.model_store.default_dtype`:
            bfloat16 on CUDA and on CPUs with native bfloat16 (AVX512-BF16 or AMX), where it
            is 2-3x faster; else float32).
        num_threads: if set, ``torch.set_num_threads(num_threads)`` (process-wide) at load.
        batch_size: prompts per generation batch.
        constrained: decode under the answer grammar (every answer parses). When off, the model
            writes freely after ``prefill`` up to ``max_new_tokens``.
        max_new_tokens: token limit of a free answer (constrained answers use the grammar's
            exact bound, about 36 tokens).
        temperature: 0 for greedy decoding (deterministic); > 0 samples.
        top_p: nucleus sampling mass when sampling.
        system_prompt: system message; ``None`` keeps the chat template's default.
        prefill: text the free answer starts with (constrained answers always start ``pan:``).
        prefix_reuse: constrained decoding: keep the key/value cache of each prompt's shared
            part (chat template, task, format, rules, grid: everything before the state
            marker, since PIRL's prompts put the state last), computed once alone, and compute
            only the state and the answer per prompt, across prompts and batches. Answers are
            the same up to floating-point rounding (as with another batch size), so it is not
            part of :meth:`settings_key`.
    """

    name = "local"

    def __init__(
        self,
        model: str | os.PathLike[str] | None = None,
        *,
        cache_dir: str | os.PathLike[str] | None = None,
        device: str | None = None,
        dtype: str | None = None,
        num_threads: int | None = None,
        batch_size: int = 16,
        constrained: bool = True,
        max_new_tokens: int = 48,
        temperature: float = 0.0,
        top_p: float = 1.0,
        system_prompt: str | None = None,
        prefill: str = PREFILL,
        prefix_reuse: bool = True,
    ) -> None:
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        if max_new_tokens < 1:
            raise ValueError(f"max_new_tokens must be >= 1, got {max_new_tokens}")
        if temperature < 0:
            raise ValueError(f"temperature must be >= 0, got {temperature}")
        import torch

        self.model_dir = resolve_model_dir(model, cache_dir)
        self.model = self.model_dir.name
        self.label = f"local:{self.model}"
        if num_threads is not None:
            torch.set_num_threads(int(num_threads))
        self.device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        self.dtype = dtype or default_dtype(self.device)
        self.batch_size = int(batch_size)
        self.constrained = bool(constrained)
        self.max_new_tokens = int(max_new_tokens)
        self.temperature = float(temperature)
        self.top_p = float(top_p)
        self.system_prompt = system_prompt
        self.prefill = PREFILL if self.constrained else prefill

        self.tokenizer, self.lm = load_model(self.model_dir, self.device, self.dtype)
        self.grammar = Grammar(self.tokenizer) if self.constrained else None
        self.prefix_reuse = bool(prefix_reuse)
        # Shared prefixes (chat text up to the state marker) -> (token ids, key/value cache).
        self._prefixes: dict[str, tuple[list[int], Any]] = {}

    def with_settings(self, **changes: Any) -> LocalAdvisor:
        """A copy sharing this one's loaded model, with other generation settings.

        Accepts ``batch_size``, ``constrained``, ``max_new_tokens``, ``temperature``, ``top_p``,
        ``system_prompt`` and ``prefill``.
        """
        allowed = {
            "batch_size",
            "constrained",
            "max_new_tokens",
            "temperature",
            "top_p",
            "system_prompt",
            "prefill",
        }
        unknown = set(changes) - allowed
        if unknown:
            raise ValueError(f"unknown settings {sorted(unknown)}; allowed: {sorted(allowed)}")
        other = copy.copy(self)
        other._prefixes = {}  # its own: another system prompt makes other prefixes
        for name, value in changes.items():
            setattr(other, name, value)
        if other.constrained:
            other.prefill = PREFILL
            other.grammar = self.grammar or Grammar(self.tokenizer)
        else:
            other.grammar = None
        return other

    def settings_key(self) -> str:
        """Generation settings that change answers (not device, threads or batch size)."""
        settings = {
            "constrained": self.constrained,
            "max_new_tokens": None if self.constrained else self.max_new_tokens,
            "temperature": self.temperature,
            "top_p": self.top_p if self.temperature > 0 else None,
            "system_prompt": self.system_prompt,
            "prefill": self.prefill,
            "dtype": self.dtype,
        }
        return json.dumps(settings, sort_keys=True)

    def chat_text(self, prompt: str) -> str:
        """The exact text the model reads for ``prompt``: chat template plus the prefill."""
        messages = [{"role": "user", "content": prompt}]
        if self.system_prompt is not None:
            messages.insert(0, {"role": "system", "content": self.system_prompt})
        text = self.tokenizer.apply_chat_template(
            messages, tokenize=False, add_generation_prompt=True
        )
        return str(text) + self.prefill

    def advise(self, prompts: list[str], views: Sequence[Any] | None = None) -> list[Answer]:
        """Answers in prompt order; prompts of similar length are batched together."""
        answers: list[Answer | None] = [None] * len(prompts)
        try:
            texts = [self.chat_text(p) for p in prompts]
            lengths = [
                len(ids) for ids in self.tokenizer(texts, add_special_tokens=False)["input_ids"]
            ]
        except Exception as exc:  # noqa: BLE001 - never raise for a failed call
            return [error_answer(f"{type(exc).__name__}: {exc}") for _ in prompts]
        order = sorted(range(len(prompts)), key=lambda i: lengths[i])
        for start in range(0, len(order), self.batch_size):
            chunk = order[start : start + self.batch_size]
            for index, answer in zip(chunk, self._generate([texts[i] for i in chunk]), strict=True):
                answers[index] = answer
        return [a if a is not None else error_answer("no answer") for a in answers]

    def _generate(self, texts: list[str]) -> list[Answer]:
        started = time.perf_counter()
        try:
            batch = self.tokenizer(
                texts, return_tensors="pt", padding=True, add_special_tokens=False
            ).to(self.device)
            prompt_tokens = batch["attention_mask"].sum(dim=1).tolist()
            if self.grammar is not None and self.prefix_reuse:
                answers_tokens = self._decode_with_prefix(texts)
            else:
                answers_tokens = self._decode(batch["input_ids"], batch["attention_mask"])
        except Exception as exc:  # noqa: BLE001 - never raise for a failed call
            elapsed = time.perf_counter() - started
            return [error_answer(f"{type(exc).__name__}: {exc}", elapsed) for _ in texts]
        elapsed = time.perf_counter() - started
        answers = []
        for tokens, n_prompt in zip(answers_tokens, prompt_tokens, strict=True):
            text = self.prefill + self.tokenizer.decode(tokens, skip_special_tokens=True)
            answers.append(
                Answer(
                    text=text,
                    recommendation=parse_recommendation(text),
                    latency_s=elapsed,
                    prompt_tokens=int(n_prompt),
                    completion_tokens=len(tokens),
                )
            )
        return answers

    def _prefix_of(self, text: str, ids: list[int]) -> tuple[str, list[int]] | None:
        """The shared part of a chat text: everything up to the prompt's state marker
        (:data:`~pirl.advice.prompt.STATE_MARKER`), with its tokens, when the text's own
        tokens start with them (a prompt without the marker, or one whose tokens merge across
        it, has none)."""
        cut = text.find(STATE_MARKER)
        if cut < 0:
            return None
        head = text[: cut + len(STATE_MARKER)]
        kept = self._prefixes.get(head)
        head_ids = kept[0] if kept is not None else None
        if head_ids is None:
            head_ids = self.tokenizer(head, add_special_tokens=False)["input_ids"]
        if len(head_ids) < MIN_PREFIX or len(ids) <= len(head_ids):
            return None
        return (head, head_ids) if ids[: len(head_ids)] == head_ids else None

    def _prefix_cache(self, head: str, head_ids: list[int], rows: int) -> Any:
        """A private copy of ``head``'s key/value cache, one row per prompt (computed once,
        alone, so an answer never depends on which prompts came before)."""
        import torch

        kept = self._prefixes.pop(head, None)
        if kept is None:
            out = self.lm(
                input_ids=torch.tensor([head_ids], device=self.device),
                use_cache=True,
                logits_to_keep=1,
            )
            kept = (head_ids, cache_of(out))
        self._prefixes[head] = kept  # most recently used last
        while len(self._prefixes) > MAX_PREFIXES:
            self._prefixes.pop(next(iter(self._prefixes)))
        cache = copy.deepcopy(kept[1])  # decoding appends to it; the kept one stays as it is
        cache.batch_repeat_interleave(rows)
        return cache

    def _decode_with_prefix(self, texts: list[str]) -> list[list[int]]:
        """Constrained decoding of ``texts``; rows that share a prefix (their text up to the
        state marker) are decoded together from its kept key/value cache, the others whole."""
        import torch

        rows = self.tokenizer(texts, add_special_tokens=False)["input_ids"]
        groups: dict[str | None, list[int]] = {}
        heads: dict[str, list[int]] = {}
        for i, (text, ids) in enumerate(zip(texts, rows, strict=True)):
            found = self._prefix_of(text, ids)
            if found is not None:
                heads[found[0]] = found[1]
            groups.setdefault(found[0] if found is not None else None, []).append(i)
        pad = self.tokenizer.pad_token_id
        out: list[list[int]] = [[] for _ in rows]
        for head, members in groups.items():
            start = len(heads[head]) if head is not None else 0
            tails = [rows[i][start:] for i in members]
            width = max(len(t) for t in tails)
            ids = torch.full((len(members), width), pad, dtype=torch.long)
            mask = torch.zeros((len(members), width), dtype=torch.long)
            for k, tail in enumerate(tails):  # left-padded after the shared prefix, masked
                ids[k, width - len(tail) :] = torch.tensor(tail)
                mask[k, width - len(tail) :] = 1
            with torch.inference_mode():
                past = self._prefix_cache(head, heads[head], len(members)) if head else None
            answers = self._decode(ids.to(self.device), mask.to(self.device), past, start)
            for i, tokens in zip(members, answers, strict=True):
                out[i] = tokens
        return out

    def _decode(
        self, ids: torch.Tensor, mask: torch.Tensor, past: Any = None, past_len: int = 0
    ) -> list[list[int]]:
        """Each row's answer tokens for a left-padded batch, up to its end token: under the
        grammar (:func:`~pirl.advice.decoding.grammar_decode`, after ``past``, the key/value
        cache of ``past_len`` tokens every row shares) or by plain ``generate``."""
        import torch

        if self.grammar is not None:
            with torch.inference_mode():
                return grammar_decode(
                    self.lm, self.grammar, ids, mask, self.tokenizer.pad_token_id,
                    self.temperature, self.top_p, past=past, past_len=past_len,
                )  # fmt: skip
        kwargs: dict[str, Any] = {
            "pad_token_id": self.tokenizer.pad_token_id,
            "eos_token_id": self.tokenizer.eos_token_id,
            "max_new_tokens": self.max_new_tokens,
        }
        if self.temperature > 0:
            kwargs.update(do_sample=True, temperature=self.temperature, top_p=self.top_p)
        else:
            kwargs.update(do_sample=False, temperature=None, top_p=None, top_k=None)
        with torch.inference_mode():
            output = self.lm.generate(input_ids=ids, attention_mask=mask, **kwargs)
        stop = set(_as_list(self.tokenizer.eos_token_id)) | {self.tokenizer.pad_token_id}
        return [_until(row, stop) for row in output[:, ids.shape[1] :].tolist()]

    def __repr__(self) -> str:
        return (
            f"LocalAdvisor(model={str(self.model_dir)!r}, device={self.device!r}, "
            f"constrained={self.constrained})"
        )


def _as_list(value: int | Iterable[int] | None) -> list[int]:
    if value is None:
        return []
    if isinstance(value, int):
        return [value]
    return list(value)


def _until(tokens: list[int], stop: set[int]) -> list[int]:
    for i, token in enumerate(tokens):
        if token in stop:
            return tokens[:i]
    return tokens
