"""The register bus of the front ends (``reg_we``, ``reg_addr``, ``reg_data``) at port level."""
from __future__ import annotations


def bus_writes(writes, *, data_width: int = 32) -> list[tuple[int, str, int]]:
    """DSP register writes ``(cycle, addr, value)`` -> port-level writes for
    :func:`cosim.pysim.run_stream` / Verilator: ``reg_we`` high for one cycle with
    ``reg_addr`` and ``reg_data``; at most one write per cycle."""
    ws = sorted((int(c), int(a), int(v)) for c, a, v in writes)
    cyc = [c for c, _, _ in ws]
    if len(set(cyc)) != len(cyc):
        raise ValueError("at most one register write per cycle")
    out = []
    busy = set(cyc)
    for c, a, v in ws:
        out += [(c, "reg_we", 1), (c, "reg_addr", a), (c, "reg_data", v & ((1 << data_width) - 1))]
        if c + 1 not in busy:
            out.append((c + 1, "reg_we", 0))
    return sorted(out, key=lambda w: w[0])
