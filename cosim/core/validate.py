"""Input validation shared by the command line, the run configurations and the studies.

One place for the rules every entry point applies *before* any work starts (STYLE.md,
"Parameters and errors"): the message states the rule and repeats the bad value, so a user
sees at once what to change. The checks raise :class:`ValueError` (the command line turns
it into one line on stderr and exit 2); :func:`warn` writes a warning line on stderr for an
option that has no effect in the run asked for.

* numbers: :func:`check_int`, :func:`check_float`, :func:`check_choice`;
* machine limits: :func:`check_jobs` (worker processes, bounded by the cores),
  :func:`check_memory` (estimated bytes against the machine's memory), :func:`check_budget`
  (a run's memory and wall time, estimated from its configuration, against the machine's
  memory and :data:`MAX_RUN_S`; every receiver and backend states its own estimate);
* output paths: :func:`check_out_dir`, :func:`check_out_file` (creatable, writable -- a probe
  file is created and removed, so a read-only place is refused also as root --, not a
  file where a directory is wanted, suffix);
* JSON: :func:`json_safe` / :func:`dumps` (non-finite floats become ``null``, never the
  invalid ``NaN``/``Infinity`` tokens).
"""
from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import numpy as np

__all__ = ["check_int", "check_float", "check_choice", "check_jobs", "check_memory",
           "check_budget", "check_out_dir", "check_out_file", "json_safe", "dumps", "warn",
           "cores", "memory_bytes", "MAX_LIST_VALUES", "MAX_RUN_S", "MAX_STUDY_S", "NOTE_RUN_S"]

#: Most values a range or list option (``--snr-db a:b:s``, ``--param``) may expand to.
MAX_LIST_VALUES = 1000
#: Share of the machine's memory one run may plan to use (the machine is shared).
MEMORY_SHARE = 0.5
#: Longest run a command starts (s of estimated wall time on this machine).
MAX_RUN_S = 2 * 3600.0
#: Longest study (a sweep's points, a fault study's runs) started (s of estimated CPU time
#: spread over the cores): studies are meant to run for hours.
MAX_STUDY_S = 48 * 3600.0
#: A run estimated to take longer than this says so on stderr before it starts
#: (:func:`check_budget` with ``note=True``).
NOTE_RUN_S = 60.0


def check_int(name: str, value, lo: int | None = None, hi: int | None = None) -> int:
    """An integer (not a bool, not a float such as 4.5) within ``[lo, hi]``."""
    ok = not isinstance(value, bool) and isinstance(value, (int, np.integer))
    if ok and (lo is None or value >= lo) and (hi is None or value <= hi):
        return int(value)
    rng = (f" in [{lo}, {hi}]" if lo is not None and hi is not None else
           f" >= {lo}" if lo is not None else f" <= {hi}" if hi is not None else "")
    raise ValueError(f"{name} must be an integer{rng}, not {value!r}")


def check_float(name: str, value, lo: float | None = None, hi: float | None = None, *,
                lo_open: bool = False, hi_open: bool = False, unit: str = "") -> float:
    """A finite number within ``lo .. hi`` (open ends with ``lo_open``/``hi_open``)."""
    u = f" {unit}" if unit else ""
    ok = (not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
          and math.isfinite(value))
    if ok:
        v = float(value)
        ok = ((lo is None or (v > lo if lo_open else v >= lo)) and
              (hi is None or (v < hi if hi_open else v <= hi)))
    if ok:
        return float(value)
    parts = []
    if lo is not None:
        parts.append(f"{'>' if lo_open else '>='} {lo:g}{u}")
    if hi is not None:
        parts.append(f"{'<' if hi_open else '<='} {hi:g}{u}")
    rule = " and ".join(parts)
    raise ValueError(f"{name} must be a finite number{' ' + rule if rule else ''}, "
                     f"not {value!r}")


def check_choice(name: str, value, choices) -> str:
    if value not in tuple(choices):
        raise ValueError(f"{name} must be one of {', '.join(map(str, choices))}, "
                         f"not {value!r}")
    return value


def cores() -> int:
    """CPU cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def check_jobs(jobs, name: str = "--jobs") -> int:
    """Worker processes: ``None`` = all cores; otherwise 1 .. the number of cores."""
    n = cores()
    if jobs is None:
        return n
    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or not 1 <= jobs <= n:
        raise ValueError(f"{name} must be an integer in [1, {n}] (the cores of this machine; "
                         f"leave it out for all of them), not {jobs!r}")
    return int(jobs)


def memory_bytes() -> int:
    """Physical memory of the machine (bytes)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def check_memory(need_bytes: float, what: str, option: str, limit_hint: str = "") -> None:
    """Refuse a run whose estimated memory exceeds :data:`MEMORY_SHARE` of the machine's."""
    cap = MEMORY_SHARE * memory_bytes()
    if not math.isfinite(need_bytes) or need_bytes > cap:
        hint = f"; {limit_hint}" if limit_hint else ""
        raise ValueError(f"{what} needs about {need_bytes / 2**30:.3g} GiB, more than the "
                         f"{cap / 2**30:.3g} GiB a run may use on this machine "
                         f"({100 * MEMORY_SHARE:g} % of {memory_bytes() / 2**30:.3g} GiB): "
                         f"reduce {option}{hint}")


def _duration(s: float) -> str:
    return f"{s:.3g} s" if s < 120 else f"{s / 60:.3g} min" if s < 7200 else f"{s / 3600:.3g} h"


def check_budget(what: str, options: str, *, memory_bytes: float = 0.0,
                 seconds: float = 0.0, max_seconds: float | None = None,
                 note: bool = False) -> None:
    """Refuse, before any work, a run too big for this machine, from an estimate of its
    configuration (the one size rule every receiver and backend applies).

    Parameters
    ----------
    what : str
        The run's size in the user's terms, e.g. ``"2,500,000 blocks x 1 trial on the fast
        backend (--duration-s 2 / 0.8 us a block)"``; the message starts with it.
    options : str
        The options that make the run smaller, e.g. ``"--duration-s, --trials or raise
        --snapshots"``; the message ends with ``reduce <options>``.
    memory_bytes : float
        Estimated peak memory (bytes): refused above :data:`MEMORY_SHARE` of the machine's
        memory (:func:`check_memory`).
    seconds : float
        Estimated wall time (s): refused above ``max_seconds`` (default :data:`MAX_RUN_S`;
        the studies give :data:`MAX_STUDY_S`).
    note : bool
        Also say on stderr (:func:`warn`) how long an accepted run estimated above
        :data:`NOTE_RUN_S` will take (the command line does; studies building many runs
        do not).

    A non-finite estimate (a run without end) is refused too."""
    check_memory(memory_bytes, what, options)
    limit = MAX_RUN_S if max_seconds is None else max_seconds
    if not math.isfinite(seconds):
        raise ValueError(f"{what} has no finite run time: reduce {options}")
    if seconds > limit:
        raise ValueError(f"{what} would take about {_duration(seconds)} on this machine "
                         f"(limit {_duration(limit)}): reduce {options}")
    if note and seconds > NOTE_RUN_S:
        warn(f"{what}: about {_duration(seconds)} estimated")


def _probe(d: Path, path, option: str) -> None:
    """Create and remove a file in the existing directory ``d`` (``os.access`` says yes to
    root also where nothing can be written, e.g. ``/proc``)."""
    import tempfile
    try:
        fd, name = tempfile.mkstemp(prefix=".cosim-probe-", dir=d)
        os.close(fd)
        os.unlink(name)
    except OSError as e:
        raise ValueError(f"{option} {str(path)!r} is not writable (cannot create a file in "
                         f"{str(d)!r}: {e.strerror or e})") from None


def _nearest_existing(p: Path) -> Path:
    q = p
    while not q.exists():
        if q.parent == q:
            break
        q = q.parent
    return q


def check_out_dir(path, option: str) -> Path:
    """An output directory: non-empty, not an existing file, creatable and writable (a probe
    file is created and removed in it, or in its nearest existing parent). Nothing else is
    created here."""
    if path is None or str(path).strip() == "":
        raise ValueError(f"{option} needs a directory name, not an empty string")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ValueError(f"{option} {str(path)!r} is an existing file, not a directory")
    base = _nearest_existing(p.resolve())
    if not base.is_dir():
        raise ValueError(f"{option} {str(path)!r} cannot be created: {str(base)!r} is a file")
    if not os.access(base, os.W_OK | os.X_OK):
        raise ValueError(f"{option} {str(path)!r} is not writable (no write permission "
                         f"in {str(base)!r})")
    _probe(base, path, option)
    return p


def check_out_file(path, option: str, suffixes=None) -> Path:
    """An output file: non-empty, not a directory, its directory creatable and writable, and
    (with ``suffixes``) one of those suffixes (the format is taken from it)."""
    if path is None or str(path).strip() == "":
        raise ValueError(f"{option} needs a file name, not an empty string")
    p = Path(path)
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise ValueError(f"{option} takes the format from the file suffix "
                         f"({' or '.join(suffixes)}), not {str(path)!r}")
    if p.is_dir():
        raise ValueError(f"{option} {str(path)!r} is a directory, not a file")
    if p.exists():
        try:
            open(p, "ab").close()       # appends nothing: the file is left as it was
        except OSError as e:
            raise ValueError(f"{option} {str(path)!r} is not writable "
                             f"({e.strerror or e})") from None
    check_out_dir(p.parent if str(p.parent) else ".", f"the directory of {option}")
    return p


def json_safe(v):
    """``v`` with every non-finite float (NaN, +-inf) replaced by ``None`` and numpy scalars
    and arrays made plain, recursively."""
    if isinstance(v, dict):
        return {k: json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_safe(x) for x in v]
    if isinstance(v, np.ndarray):
        return json_safe(v.tolist())
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    return v


def dumps(obj, **kw) -> str:
    """JSON text that is always valid JSON (``allow_nan=False`` after :func:`json_safe`)."""
    return json.dumps(json_safe(obj), allow_nan=False, **kw)


def warn(msg: str) -> None:
    """A warning line on stderr (an option without effect, an estimate, ...)."""
    print(f"warning: {msg}", file=sys.stderr)
