"""Record layouts: the fields of a front end's FIFO record, their widths and signedness,
and the codec between field values, the record as one integer and its FIFO words.

One :class:`RecordLayout` describes a front end's record for every side that reads or
writes it: the bit-exact model packs its records with :meth:`RecordLayout.pack`, the HDL
builds its record struct from :attr:`RecordLayout.fields`, and the DSP decodes received
records with :meth:`RecordLayout.unpack`. Fields are laid out LSB first; a signed field is
stored in two's complement. A record wider than a FIFO word is split into
``record_words`` words, least significant word first (:meth:`RecordLayout.to_words`), the
order :func:`dsp.records.receive_records` reassembles.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple


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
