"""The answer grammar: ``pan: <n>, tilt: <n>, zoom: <n>, X: <n>, Y: <n>, Z: <n>`` as a
token-level constraint (decoded by :mod:`pirl.advice.decoding`).

A 135M model does not follow the output format by itself. The answer is prefilled with
:data:`PREFILL` and decoded under this grammar: the key names and separators are forced, and
the model only chooses the numbers, among strings that are in range. The allowed values
derive from :mod:`pirl.config.grid`, so every answer parses onto the action grid. The grammar
is built from the tokenizer's own pieces, so it works for other tokenizers too.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pirl.config import grid

__all__ = ["PREFILL", "Grammar", "field_values"]

PREFILL = "pan:"
"""Text a constrained answer starts with: the first field's key."""

_VALUE_CHARS = frozenset(" -.0123456789")


def field_values() -> list[tuple[str, list[str]]]:
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


class Grammar:
    """Token-level grammar of ``pan: <n>, tilt: <n>, zoom: <n>, X: <n>, Y: <n>, Z: <n>``.

    Literals (", tilt:") are forced token by token; a value is any sequence of numeric tokens
    (digits, ".", "-", one leading space) whose text is a prefix of an allowed value; a value may
    end once its text is a complete allowed value.

    Raises:
        ValueError: a key literal starts with a numeric token (the tokenizer cannot be
            constrained this way).
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
        for literal, values in field_values():
            ids = tokenizer(literal, add_special_tokens=False)["input_ids"] if literal else []
            if literal and (not ids or ids[0] in self.pieces):
                raise ValueError(f"cannot constrain this tokenizer: literal {literal!r}")
            self.literals.append(list(ids))
            self.complete.append(frozenset(values))
            self.prefixes.append(frozenset(v[:n] for v in values for n in range(len(v) + 1)))
        # Longest answer, in tokens: every literal token, one token per value character plus
        # its leading space, and the end token.
        longest = sum(len(ids) for ids in self.literals)
        longest += sum(max(len(v) for v in values) + 1 for _, values in field_values())
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
