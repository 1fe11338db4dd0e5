"""The TACAN sweep's records: what a user sees of them."""
from cosim.studies.spec import SweepConfig
from cosim.tacan.study import TacanSweepRecord


def test_a_record_whose_bearings_are_all_flagged_is_unavailable_not_accurate():
    """A 4-bit ADC at 20 dB leaves the noise under-dithered (sigma ~0.3 LSB): quantised, it
    is sparse and impulsive, and the pair search, whose threshold is a multiple of the mean
    floor, passes thousands of noise pairs a second. The DSP's filter fits them and flags
    every bearing (its noise estimate beside the pulse level). The sweep counts that record
    as unavailable (no epoch with a valid bearing) and leaves it out of the accuracy; one
    more ADC bit shows valid bearings."""
    cfg = SweepConfig(params=(("adc_bits", (4, 5)),), snr_db=(20.0,), trials=9,
                      duration_s=1.0, recheck=0)
    rec = TacanSweepRecord(cfg, 20.0, 8, cfg.combos)
    four = rec.point((("adc_bits", 4),))
    assert four["n_bearings"] > 0 and four["n_valid_bearings"] == 0
    assert four["rmse_deg"] > 1.0          # every bearing, flagged ones included
    s4 = four["shown"]
    assert s4["n_valid"] == 0 and s4["rmse"] is None and s4["availability"] == 0.0
    assert s4["n_epochs"] == 7 and s4["misleading"] == 0
    five = rec.point((("adc_bits", 5),))
    s5 = five["shown"]
    assert s5["n_valid"] > 0 and s5["rmse"] < 0.1 and s5["availability"] == 1.0
    assert s5["misleading"] == 0 and five["misleading_bearings"] == 0


def test_a_study_chooses_one_detector_for_its_points_and_its_golden_chain():
    """``detector`` is a study parameter with one value: each record's golden run is shared
    by all its points, so a study of the single-pulse receiver runs its golden chain with
    single pulses too; several values are refused before any point runs."""
    import pytest

    from cosim.studies.sweep import check_points
    from cosim.tacan.study import run_config, study_detector, trial_signal
    cfg = SweepConfig(params=(("adc_bits", (5, 6)), ("detector", ("pulse",))), recheck=0)
    assert study_detector(cfg) == "pulse"
    assert study_detector(SweepConfig(params=(("adc_bits", (5, 6)),), recheck=0)) == "both"
    check_points(cfg)
    combo = cfg.combos[0]
    assert run_config(cfg, combo, trial_signal(cfg, 10.0, 0)).detector == "pulse"
    two = SweepConfig(params=(("adc_bits", (5,)), ("detector", ("pulse", "both"))), recheck=0)
    with pytest.raises(ValueError, match="one detector per study"):
        check_points(two)
    bad = SweepConfig(params=(("detector", ("pulses",)),), recheck=0)
    with pytest.raises(ValueError, match="detector"):
        check_points(bad)
