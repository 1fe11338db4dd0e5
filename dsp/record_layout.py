"""Record layouts: the fields of a front end's FIFO record, their widths and signedness,
and the codec between field values, the record as one integer and its FIFO words.

One :class:`RecordLayout` describes a front end's record for every side that reads or
writes it: the bit-exact model packs its records with :meth:`RecordLayout.pack`, the HDL
builds its record struct from :attr:`RecordLayout.fields`, and the DSP decodes received
records with :meth:`RecordLayout.unpack` (many records at once:
:meth:`RecordLayout.to_word_array`, :meth:`RecordLayout.from_word_array`). Fields are laid out LSB first; a signed field is
stored in two's complement. A record wider than a FIFO word is split into
``record_words`` words, least significant word first (:meth:`RecordLayout.to_words`), the
order :func:`dsp.records.receive_records` reassembles.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


class Field(NamedTuple):
    """One record field: its name, width in bits and whether it is two's complement."""

    name: str
    width: int
    signed: bool = False


@dataclass(frozen=True)
class RecordLayout:
    """The fields of a record, LSB first.

    Parameters
    ----------
    fields : sequence of Field or (name, width, signed) tuples
        The fields from the least significant bit up; names unique, widths >= 1.
    """

    fields: tuple[Field, ...]

    def __post_init__(self):
        try:
            fs = tuple(Field(*f) for f in self.fields)
        except TypeError as e:
            raise ValueError(f"record fields must be (name, width, signed) tuples: {e}") from None
        for f in fs:
            if not isinstance(f.name, str) or not f.name:
                raise ValueError(f"record field name must be a non-empty string, not {f.name!r}")
            if isinstance(f.width, bool) or not isinstance(f.width, int) or f.width < 1:
                raise ValueError(f"record field {f.name!r} width must be an int >= 1, "
                                 f"not {f.width!r}")
        names = [f.name for f in fs]
        if len(set(names)) != len(names):
            raise ValueError(f"record field names must be unique, not {names}")
        object.__setattr__(self, "fields", fs)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(f.name for f in self.fields)

    @property
    def bits(self) -> int:
        """Width of the whole record."""
        return sum(f.width for f in self.fields)

    def words(self, width: int) -> int:
        """The fewest ``width``-bit FIFO words that hold the record."""
        return -(-self.bits // int(width))

    def pack(self, values) -> int:
        """Field values (a mapping with every field's name) -> the record as one int.
        Each value is taken modulo ``2**width`` (two's complement for signed fields)."""
        v, pos = 0, 0
        for name, w, _ in self.fields:
            v |= (int(values[name]) & ((1 << w) - 1)) << pos
            pos += w
        return v

    def unpack(self, value: int) -> dict:
        """The record as one int -> ``{name: value}`` (signed fields sign-extended)."""
        out, pos = {}, 0
        for name, w, s in self.fields:
            x = (int(value) >> pos) & ((1 << w) - 1)
            if s and x >> (w - 1):
                x -= 1 << w
            out[name] = x
            pos += w
        return out

    def to_words(self, value: int, width: int, record_words: int | None = None) -> list[int]:
        """The record as ``record_words`` FIFO payload words of ``width`` bits, least
        significant first (default: the fewest that hold it, :meth:`words`)."""
        n = self.words(width) if record_words is None else int(record_words)
        m = (1 << int(width)) - 1
        return [(int(value) >> (j * int(width))) & m for j in range(n)]

    # -- many records at once (numpy) ----------------------------------------------------
    def to_word_array(self, values, width: int, record_words: int | None = None):
        """:meth:`to_words` of :meth:`pack` for many records: ``values`` an ``(n, fields)``
        integer array (columns in field order, each taken modulo ``2**width`` of its
        field) -> ``(n, record_words)`` int64 words (words and fields of at most 62 bits)."""
        n = self.words(width) if record_words is None else int(record_words)
        v = np.asarray(values, np.int64)
        if v.ndim != 2 or v.shape[1] != len(self.fields):
            raise ValueError(f"values must be an (n, {len(self.fields)}) array, not of shape "
                             f"{v.shape}")
        pc = _pieces(self, int(width), n)
        parts = ((v.view(np.uint64)[:, pc.field] >> pc.frm) & pc.mask) << pc.at
        out = np.zeros((v.shape[0], n), np.uint64)
        if v.shape[0]:
            out[:, pc.words] = np.bitwise_or.reduceat(parts, pc.word_starts, axis=1)
        return out.view(np.int64)

    def from_word_array(self, words, width: int):
        """:meth:`unpack` of many records from their FIFO words: ``(n, record_words)`` ->
        ``(n, fields)`` int64 (signed fields sign-extended)."""
        w = np.ascontiguousarray(words, np.int64)
        if w.ndim != 2:
            raise ValueError(f"words must be an (n, record_words) array, not of shape {w.shape}")
        pc = _pieces(self, int(width), w.shape[1])
        if not w.shape[0]:
            return np.zeros((0, len(self.fields)), np.int64)
        parts = ((w.view(np.uint64)[:, pc.word] >> pc.at) & pc.mask) << pc.frm
        out = np.bitwise_or.reduceat(parts, pc.field_starts, axis=1).view(np.int64)
        return (out ^ pc.sign) - pc.sign


class _Pieces(NamedTuple):
    """The parts of the fields that fall in one word each, in field order (so in word
    order too): per part its field, word, first bit in the word (``at``) and in the field
    (``frm``) and bit mask; where each field's and each word's parts start; the sign bit of
    each signed field (0 for an unsigned one)."""

    field: np.ndarray
    word: np.ndarray
    at: np.ndarray
    frm: np.ndarray
    mask: np.ndarray
    field_starts: np.ndarray
    words: np.ndarray
    word_starts: np.ndarray
    sign: np.ndarray


@functools.lru_cache(maxsize=64)
def _pieces(layout: RecordLayout, width: int, record_words: int):
    """Where each field's bits go in ``record_words`` words of ``width`` bits
    (:class:`_Pieces`; the numpy codec: words and fields of at most 62 bits)."""
    if not 1 <= width <= 62 or any(f.width > 62 for f in layout.fields):
        raise ValueError(f"the array codec takes words and fields of at most 62 bits, "
                         f"not a {width}-bit word with fields of "
                         f"{max(f.width for f in layout.fields)} bits")
    if record_words * width < layout.bits:
        raise ValueError(f"{record_words} words of {width} bits cannot hold a "
                         f"{layout.bits}-bit record")
    out, pos = [], 0
    for k, f in enumerate(layout.fields):
        lo, hi = pos, pos + f.width
        for j in range(lo // width, (hi - 1) // width + 1):
            a, b = max(lo, j * width), min(hi, (j + 1) * width)
            out.append((k, j, a - j * width, a - lo, (1 << (b - a)) - 1))
        pos = hi
    # (fields LSB first: the parts' words ascend with their fields)
    fld, wrd, at, frm, mask = (np.array(c, np.int64) for c in zip(*out))
    words, word_starts = np.unique(wrd, return_index=True)
    _, field_starts = np.unique(fld, return_index=True)
    sign = np.array([(1 << (f.width - 1)) if f.signed else 0 for f in layout.fields], np.int64)
    u = np.uint64
    return _Pieces(fld, wrd, at.astype(u), frm.astype(u), mask.astype(u), field_starts,
                   words, word_starts, sign)
