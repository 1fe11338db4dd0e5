"""What a quantisation sweep is: its configuration (:class:`SweepConfig`), the parameter
value lists of ``--param NAME=VALUES`` (:func:`parse_values`, :func:`parse_param`) and the
receiver's side of it (:func:`sweep_model`, :func:`primary_key`), shared by the engine
(:mod:`cosim.studies.sweep`) and the proposal (:mod:`cosim.studies.proposal`).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

__all__ = ["SweepConfig", "parse_values", "parse_param", "check_param", "check_recheck", "sweep_model",
           "primary_key"]


def sweep_model(receiver: str):
    """The :class:`~cosim.core.receivers.SweepModel` of a registered receiver (ValueError if it
    has none)."""
    from cosim.core.receivers import get
    r = get(receiver)
    if r.sweep is None or r.sweep.model is None:
        raise ValueError(f"receiver {receiver!r} has no sweep study model")
    return r.sweep.model


def primary_key(receiver: str) -> str:
    """The receiver's primary figure (``Receiver.primary.key``), e.g. ``rmse_deg``."""
    from cosim.core.receivers import get
    return get(receiver).primary.key


# -- parameter specifications -----------------------------------------------------------
def parse_values(spec: str, option: str = "values") -> tuple:
    """``"4:14"`` -> 4..14, ``"0:20:5"`` -> 0, 5, ..., 20, ``"8,12,16"`` or ``"floor,half_up"``
    -> the list (numbers where they parse); at most :data:`cosim.core.validate.MAX_LIST_VALUES`
    values (counted before any list is built)."""
    from cosim.core.validate import MAX_LIST_VALUES
    spec = spec.strip()
    if not spec:
        raise ValueError(f"{option}: empty value list")
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) not in (2, 3):
            raise ValueError(f"range must be a:b or a:b:step, not {spec!r}")
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            raise ValueError(f"range bounds must be numbers, not {spec!r}") from None
        a, b = nums[0], nums[1]
        st = nums[2] if len(nums) == 3 else 1.0
        if not all(math.isfinite(v) for v in nums) or st <= 0 or b < a:
            raise ValueError(f"range {spec!r} must have finite a <= b and step > 0")
        n = math.floor((b - a) / st + 1e-9) + 1
        if n > MAX_LIST_VALUES:
            raise ValueError(f"{option} {spec!r} gives {n:,} values; at most "
                             f"{MAX_LIST_VALUES} (use a larger step)")
        vals = [a + i * st for i in range(n)]
        if all(float(v).is_integer() for v in nums):
            return tuple(int(round(v)) for v in vals)
        return tuple(round(v, 12) for v in vals)
    out = []
    items = spec.split(",")
    if len(items) > MAX_LIST_VALUES:
        raise ValueError(f"{option} gives {len(items):,} values; at most {MAX_LIST_VALUES}")
    for p in items:
        p = p.strip()
        if not p:
            raise ValueError(f"{option}: empty item in {spec!r}")
        try:
            v = float(p)
            out.append(int(v) if v.is_integer() and "." not in p else v)
        except ValueError:
            out.append(p)
    return tuple(out)


def parse_param(text: str, receiver: str = "tacan") -> tuple[str, tuple]:
    """``"NAME=VALUES"`` -> ``(NAME, values)`` (name checked by :func:`check_param`)."""
    if "=" not in text:
        raise ValueError(f"--param must be NAME=VALUES, not {text!r}")
    name, spec = text.split("=", 1)
    name = name.strip()
    check_param(name, receiver)
    return name, parse_values(spec, f"--param {name}")


def check_recheck(cfg: "SweepConfig", given: bool) -> None:
    """``--recheck`` (``given`` on the command line, at its default value too) asks for no
    more points than the sweep has (the re-checks pick among its combinations); left at
    its default, the sweep re-checks at most that many (all of a smaller sweep)."""
    n = len(cfg.combos)
    if given and cfg.recheck > n:
        raise ValueError(f"--recheck {cfg.recheck} is more than the {n} point"
                         f"{'s' if n != 1 else ''} it picks from (the combinations of the "
                         f"swept values)")


def check_param(name: str, receiver: str = "tacan") -> None:
    """Refuse a parameter the receiver's sweep model does not know (ValueError)."""
    sweep_model(receiver).check_param(name)


# -- the sweep's configuration ------------------------------------------------------------
@dataclass(frozen=True)
class SweepConfig:
    """One sweep (see the module doc).

    Parameters
    ----------
    receiver : str
        A registered receiver whose sweep study has a model (:mod:`cosim.core.receivers`).
    params : tuple of (name, values)
        Swept parameters (crossed). Default: the receiver's ``SweepModel.default_params``
        (TACAN: ``adc_bits`` 4..14).
    snr_db : tuple of float
    trials : int
        Monte Carlo records per SNR (independent seeds; bearing drawn per trial).
    duration_s, memory_s : float
        Record length and the Kalman filter memory (bearings after ``2 memory_s`` count).
    seed : int
        Base seed: the same sweep gives the same bits.
    recheck : int
        Points re-run on the cycle-accurate backend (``recheck_backend``: ``"verilator"``,
        ``"pysim"``, or ``"auto"``, Verilator when installed) over the first
        ``recheck_samples`` ADC samples (default 1,000,000 with Verilator, 60,000 with the
        much slower Amaranth simulation), comparing FIFO words and cycles with the model.
    target_rel : float
        Word-length proposal: the RMSE of the estimates shown valid within
        ``(1 + target_rel)`` of the float golden chain's.
    availability_margin : float
        Word-length proposal: the fraction of epochs with a valid estimate not below the
        golden chain's by more than this (absolute; 0.02 = two epochs in a hundred).
    design : {"grid", "oat"}
        ``grid``: every combination of the swept values; ``oat``: one parameter at a time,
        the others at their reference (largest) value -- what the proposal reads, at the
        cost of a sum instead of a product of the value counts.
    """

    receiver: str = "tacan"
    params: tuple = ()
    snr_db: tuple = (0.0, 5.0, 10.0, 15.0, 20.0)
    trials: int = 20
    duration_s: float = 1.0
    memory_s: float = 0.25
    seed: int = 0
    recheck: int = 2
    recheck_backend: str = "auto"
    recheck_samples: int | None = None
    target_rel: float = 0.05
    availability_margin: float = 0.02
    design: str = "grid"

    def __post_init__(self):
        model = sweep_model(self.receiver)    # a registered receiver with a sweep model
        if not self.params:
            object.__setattr__(self, "params", tuple(model.default_params))
        names = [n for n, _ in self.params]
        if len(set(names)) != len(names):
            raise ValueError(f"parameter given twice: {names}")
        for n, vals in self.params:
            check_param(n, self.receiver)
            if not vals:
                raise ValueError(f"parameter {n} has no values")
        if not self.snr_db or not all(isinstance(s, (int, float)) and math.isfinite(s)
                                      for s in self.snr_db):
            raise ValueError(f"snr_db must be finite numbers, not {self.snr_db!r}")
        if isinstance(self.trials, bool) or not isinstance(self.trials, int) or self.trials < 1:
            raise ValueError(f"trials must be an integer >= 1, not {self.trials!r}")
        if not (math.isfinite(self.memory_s) and self.memory_s > 0):
            raise ValueError(f"memory_s must be > 0, not {self.memory_s}")
        if not (math.isfinite(self.duration_s) and self.duration_s > 2 * self.memory_s + 0.1):
            raise ValueError(f"--duration-s must exceed {2 * self.memory_s + 0.1:g} s (scoring "
                             f"starts at twice the filter memory {self.memory_s:g} s, plus "
                             f"0.1 s to score), not {self.duration_s:g}")
        if self.recheck_backend not in ("auto", "pysim", "verilator"):
            raise ValueError(f"recheck_backend must be 'auto', 'pysim' or 'verilator', not "
                             f"{self.recheck_backend!r}")
        if self.recheck_samples is not None and (
                isinstance(self.recheck_samples, bool) or
                not isinstance(self.recheck_samples, int) or self.recheck_samples < 1000):
            raise ValueError(f"recheck_samples must be an integer >= 1000, not "
                             f"{self.recheck_samples!r}")
        if not (0 < self.target_rel < 10):
            raise ValueError(f"target_rel must be in (0, 10), not {self.target_rel}")
        if not (isinstance(self.availability_margin, (int, float))
                and 0 <= self.availability_margin < 1):
            raise ValueError(f"availability_margin must be in [0, 1), not "
                             f"{self.availability_margin!r}")
        if self.design not in ("grid", "oat"):
            raise ValueError(f"design must be 'grid' (every combination) or 'oat' (one "
                             f"parameter at a time), not {self.design!r}")

    @property
    def recheck_plan(self) -> tuple[str, int]:
        """(backend, samples) the re-checks use."""
        be = self.recheck_backend
        if be == "auto":
            from cosim.backends.verilator_harness import verilator_available
            be = "verilator" if verilator_available() else "pysim"
        n = self.recheck_samples or (1_000_000 if be == "verilator" else 60_000)
        return be, n

    @property
    def reference(self) -> dict:
        """Each parameter's reference value: its largest swept value (numeric), else its
        first; the one-at-a-time design holds the others there."""
        return {n: max(v) if all(isinstance(x, (int, float)) for x in v) else v[0]
                for n, v in self.params}

    @property
    def combos(self) -> list[tuple]:
        names = [n for n, _ in self.params]
        if self.design == "grid":
            return [tuple(zip(names, vals))
                    for vals in itertools.product(*(v for _, v in self.params))]
        ref = self.reference
        out = []
        for n, vals in self.params:
            for v in vals:
                c = tuple((m, v if m == n else ref[m]) for m in names)
                if c not in out:
                    out.append(c)
        return out

    @property
    def n_points(self) -> int:
        return len(self.combos) * len(self.snr_db) * self.trials
