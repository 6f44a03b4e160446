"""Files that hold state and can never run code when read: arrays in an ``.npz``, the rest JSON.

Checkpoints and students are nested structures of dicts, lists, tuples, numbers, strings,
NumPy arrays, PyTorch tensors and a few of PIRL's own dataclasses (answers, prompt states,
scores). :func:`save` writes such a structure as one NumPy ``.npz`` archive: every array (and
tensor) as a member, and the structure around them as a JSON document in which each array
is a reference. :func:`load` reads it with ``allow_pickle=False`` and plain JSON, so a file
from anyone can only ever produce data. A dataclass is rebuilt field by field (no
``__init__`` or ``__post_init__`` runs) and only when its class is a dataclass of the
``pirl`` package itself.

Exactness: arrays keep their dtype and bytes, floats round-trip through JSON's shortest
repr, big integers (PCG64 states) stay integers, so a resumed run continues bit for bit.
"""

from __future__ import annotations

import dataclasses
import importlib
import io
import json
import os
import pickletools
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from pirl.config.errors import UserError

__all__ = ["UnsafeFile", "load", "pickle_globals", "refuse_pickle", "save"]

_STRUCTURE = "__structure__"
_BIT_GENERATORS = ("PCG64", "PCG64DXSM", "MT19937", "Philox", "SFC64")
_FORMAT = "pirl-safe-state/1"


class UnsafeFile(UserError):
    """A file that would need unpickling (which can run code) was refused."""


def refuse_pickle(path: Path, what: str = "") -> UnsafeFile:
    """The one-line refusal of a file that only a pickle loader could read."""
    kind = f" ({what})" if what else ""
    return UnsafeFile(
        f"refused {path}{kind}: it is a pickle, and loading a pickle can run any code; pirl "
        "reads only arrays and JSON from shared files (see docs/sharing.md): remove the file "
        "or make it again with this version of pirl"
    )


# -- writing -------------------------------------------------------------------------------
def _encode(obj: Any, arrays: list[np.ndarray]) -> Any:
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, int):
        return obj if type(obj) is int else {"__int__": int(obj)}
    if isinstance(obj, float):
        if obj != obj or obj in (float("inf"), float("-inf")):
            return {"__float__": repr(obj)}
        return obj
    if isinstance(obj, np.ndarray | np.generic):
        arr = np.asarray(obj)
        if arr.dtype.hasobject:
            raise TypeError("object arrays cannot be saved safely")
        arrays.append(np.ascontiguousarray(arr))
        return {"__array__": len(arrays) - 1, "scalar": isinstance(obj, np.generic)}
    if isinstance(obj, np.random.Generator):
        bits = obj.bit_generator
        return {"__generator__": type(bits).__name__, "state": _encode(bits.state, arrays)}
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency
        torch = None
    if torch is not None and isinstance(obj, torch.Tensor):
        arrays.append(np.ascontiguousarray(obj.detach().cpu().numpy()))
        return {"__tensor__": len(arrays) - 1}
    if isinstance(obj, tuple):
        return {"__tuple__": [_encode(v, arrays) for v in obj]}
    if isinstance(obj, list):
        return [_encode(v, arrays) for v in obj]
    if isinstance(obj, dict):
        if all(type(k) is str for k in obj) and not any(k.startswith("__") for k in obj):
            return {k: _encode(v, arrays) for k, v in obj.items()}
        return {"__dict__": [[_encode(k, arrays), _encode(v, arrays)] for k, v in obj.items()]}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        cls = type(obj)
        if not cls.__module__.startswith("pirl."):
            raise TypeError(f"{cls.__qualname__} is not a pirl dataclass")
        fields = {f.name: _encode(getattr(obj, f.name), arrays) for f in dataclasses.fields(obj)}
        return {"__dataclass__": f"{cls.__module__}:{cls.__qualname__}", "fields": fields}
    raise TypeError(f"cannot save a {type(obj).__name__} safely")


def save(obj: Any, path: str | os.PathLike[str]) -> Path:
    """Write ``obj`` to ``path`` (an ``.npz`` archive), flushed to disk; not atomic by itself
    (callers write into a temporary name and rename)."""
    path = Path(path)
    arrays: list[np.ndarray] = []
    structure = json.dumps({"format": _FORMAT, "data": _encode(obj, arrays)})
    members = {f"a{i}": a for i, a in enumerate(arrays)}
    members[_STRUCTURE] = np.frombuffer(structure.encode(), dtype=np.uint8)
    with open(path, "wb") as fh:
        np.savez(fh, **members)
        fh.flush()
        os.fsync(fh.fileno())
    return path


# -- reading -------------------------------------------------------------------------------
class _Decoder:
    def __init__(self, archive: Any, path: Path) -> None:
        self.archive, self.path = archive, path

    def array(self, index: int) -> np.ndarray:
        return self.archive[f"a{int(index)}"]

    def __call__(self, obj: Any) -> Any:
        if isinstance(obj, list):
            return [self(v) for v in obj]
        if not isinstance(obj, dict):
            return obj
        if "__array__" in obj:
            arr = self.array(obj["__array__"])
            return arr[()] if obj.get("scalar") else arr
        if "__tensor__" in obj:
            import torch

            return torch.from_numpy(np.array(self.array(obj["__tensor__"])))
        if "__tuple__" in obj:
            return tuple(self(v) for v in obj["__tuple__"])
        if "__generator__" in obj:
            name = str(obj["__generator__"])
            if name not in _BIT_GENERATORS:
                raise UnsafeFile(f"refused {self.path}: unknown random generator {name!r}")
            bits = getattr(np.random, name)()
            bits.state = self(obj["state"])
            return np.random.Generator(bits)
        if "__dict__" in obj:
            return {_hashable(self(k)): self(v) for k, v in obj["__dict__"]}
        if "__int__" in obj:
            return int(obj["__int__"])
        if "__float__" in obj:
            return float(obj["__float__"])
        if "__dataclass__" in obj:
            return self.dataclass(obj["__dataclass__"], obj.get("fields", {}))
        return {k: self(v) for k, v in obj.items()}

    def dataclass(self, name: str, fields: dict[str, Any]) -> Any:
        module, _, qualname = str(name).partition(":")
        if not module.startswith("pirl."):
            raise UnsafeFile(f"refused {self.path}: it names {name}, which is not pirl's")
        cls: Any = importlib.import_module(module)
        for part in qualname.split("."):
            cls = getattr(cls, part, None)
        if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
            raise UnsafeFile(f"refused {self.path}: {name} is not one of pirl's data classes")
        obj = object.__new__(cls)
        for f in dataclasses.fields(cls):
            if f.name in fields:
                value = self(fields[f.name])
            elif f.default is not dataclasses.MISSING:
                value = f.default  # a field added since the file was written
            elif f.default_factory is not dataclasses.MISSING:
                value = f.default_factory()
            else:
                raise ValueError(f"{self.path} is damaged ({name} lacks {f.name})")
            object.__setattr__(obj, f.name, value)
        return obj


def _hashable(key: Any) -> Any:
    return tuple(_hashable(k) for k in key) if isinstance(key, list | tuple) else key


def load(path: str | os.PathLike[str]) -> Any:
    """Read a :func:`save` file; nothing in it is unpickled. Raises :class:`UnsafeFile` for a
    file that is a pickle, ``ValueError`` for any other damage."""
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(2)
    if head[:1] == b"\x80":
        raise refuse_pickle(path)
    try:
        with zipfile.ZipFile(path) as members:
            if any(n.endswith((".pkl", ".pickle")) for n in members.namelist()):
                raise refuse_pickle(path, "a pickle inside a zip, as torch.save writes")
    except zipfile.BadZipFile:
        raise ValueError(f"{path} is damaged (not an archive)") from None
    except OSError as exc:
        raise ValueError(f"{path} cannot be read ({type(exc).__name__})") from None
    try:
        with np.load(path, allow_pickle=False) as archive:
            raw = bytes(archive[_STRUCTURE].tobytes())
            document = json.loads(raw.decode())
            if not isinstance(document, dict) or document.get("format") != _FORMAT:
                raise ValueError(f"{path} is not a pirl state file")
            return _Decoder(archive, path)(document["data"])
    except UnsafeFile:
        raise
    except (OSError, KeyError, zipfile.BadZipFile, EOFError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is damaged ({type(exc).__name__})") from None
    except ValueError as exc:
        # np.load refuses object arrays (they would need unpickling) with a ValueError.
        if "allow_pickle" in str(exc):
            raise refuse_pickle(path, "an array of Python objects") from None
        raise


# -- looking into a pickle without loading it ----------------------------------------------
_STRINGS = {"SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8", "UNICODE", "STRING", "BINSTRING"}
_STRINGS |= {"SHORT_BINSTRING"}


def pickle_globals(data: bytes) -> set[str]:
    """Every ``module.name`` a pickle would import (its GLOBAL, INST and STACK_GLOBAL opcodes),
    read with :mod:`pickletools` without executing anything. A STACK_GLOBAL whose operands
    cannot be followed is reported as ``'?'``."""
    found: set[str] = set()
    memo: dict[int, Any] = {}
    recent: list[Any] = []  # the values the last opcodes pushed, strings or None
    try:
        for op, arg, _pos in pickletools.genops(io.BytesIO(data)):
            name = op.name
            if name in _STRINGS:
                recent.append(arg if isinstance(arg, str) else None)
            elif name == "MEMOIZE":
                memo[len(memo)] = recent[-1] if recent else None
                continue
            elif name in ("BINPUT", "LONG_BINPUT", "PUT"):
                memo[int(arg)] = recent[-1] if recent else None
                continue
            elif name in ("BINGET", "LONG_BINGET", "GET"):
                recent.append(memo.get(int(arg)))
            elif name in ("GLOBAL", "INST"):
                found.add(str(arg).replace(" ", "."))
                recent.append(None)
            elif name == "STACK_GLOBAL":
                module, attr = (recent[-2], recent[-1]) if len(recent) >= 2 else (None, None)
                ok = isinstance(module, str) and isinstance(attr, str)
                found.add(f"{module}.{attr}" if ok else "?")
                recent.append(None)
            else:
                recent.append(None)
            del recent[:-4]
    except Exception:  # noqa: BLE001 - a pickle that cannot be read through is refused
        found.add("?")
    return found
