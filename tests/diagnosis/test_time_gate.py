"""The shared time-variation gate of the position fits (diagnosis.limbfit.gap_is_significant,
issue 20 item 1): a change that ``armimp estimate``'s time-variation test finds makes the
gap significant, so that the catalogue is fitted even when the whole-record gap averages
the change away. Data: labsim (the independent simulator), the draws of
bench/bench_time_state.py."""

from diagnosis import limbfit as lf
from labsim_trials import labsim_trial


def _record(kind, seed):
    # as the bench: no recorded reference, a band-limited noise perturbation, 60 s
    return lf.PositionRecord.from_trial(labsim_trial(kind, seed, seconds=None)[0])


class _Quiet:
    """A whole-record gap that is not significant."""

    def significant(self, cfg):
        return False


def test_a_change_in_time_makes_the_gap_significant():
    rec = _record("switching", 100)
    significant, changing = lf.gap_is_significant([rec], _Quiet(), lf.FitConfig())
    assert significant and changing == [rec.name or "record 1"]
    off = lf.gap_is_significant([rec], _Quiet(), lf.FitConfig(time_gate=False))
    assert off == (False, [])


def test_a_stationary_record_is_not_made_significant():
    rec = _record("nominal", 100)
    assert lf.changes_in_time([rec]) == []
    assert lf.gap_is_significant([rec], _Quiet(), lf.FitConfig()) == (False, [])


def test_a_state_change_averaged_away_is_named_with_the_gate():
    """bench_time_state's moving_angle_dependent seed 101: the whole-record gap is under
    its threshold, the time test finds the stiffness changing as the ankle moves."""
    rec = _record("moving_angle_dependent", 101)
    effects = ("stiffness_angle", "stiffness_drift")
    without = lf.diagnose_position([rec], lf.FitConfig(
        effects=effects, pairs=False, n_jackknife=0, time_gate=False))
    assert without.verdict == lf.VERDICT_NONE
    d = lf.diagnose_position([rec], lf.FitConfig(effects=effects, pairs=False,
                                                 n_jackknife=0))
    assert d.gap["changing_in_time"] == ["record 1"]
    assert d.verdict == lf.VERDICT_EFFECT and d.named == ["stiffness_angle"], d.ranking[:2]
