"""A plane tilted beyond the declared gravity search range is named with its angle
(issue 21, item 5): the search widens inside the physical limits and the report says so.

Two 9 s trials (one per joint, the shortest a lone trial's time split allows) made by the
project's simulator with the robot's plane tilted 40 deg, beyond the 30 deg upper bound
of the declared search; only gravity is tried, to stay within the suite's time budget.
"""

import json

import pytest

pytest.importorskip("orchestrator")

from diagnosis import VERDICT_EFFECT, DiagnosisConfig, diagnose  # noqa: E402
from diagnosis.catalogue import get_effect  # noqa: E402
from diagnosis.validation import SetSpec, make_set  # noqa: E402

TILT_DEG = 40.0


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    assert TILT_DEG > get_effect("gravity").parameters[0].bounds[1]  # beyond the range
    root = tmp_path_factory.mktemp("tilted")
    folder = make_set(SetSpec("tilted", (("gravity", {"tilt_deg": TILT_DEG}),), seeds=(1,),
                              duration_s=9.0), root)
    return diagnose(folder, root / "report",
                    config=DiagnosisConfig(effects=("gravity",), grid_points=4,
                                           refine_iterations=4), progress=False, workers=1)


def test_a_tilt_beyond_the_search_range_is_named_with_its_angle(report):
    assert (report.verdict, report.named) == (VERDICT_EFFECT, ["gravity"]), report.summary
    assert report.fitted["gravity"]["tilt_deg"] == pytest.approx(TILT_DEG, rel=0.05)
    assert report.gap["named_held_out_reduction"] > 0.9


def test_the_report_says_the_search_was_widened(report):
    data = json.loads((report.out_dir / "report.json").read_text())
    (row,) = data["ranking"]
    assert row["at_search_bound"] == []
    assert row["searched"] == {"gravity": {"tilt_deg": [0.2, 90.0]}}
    assert row["widened"] == ["gravity: tilt_deg search widened from [0.2, 30] to "
                              "[0.2, 90] (best fit at its upper bound)"]
    text = (report.out_dir / "report.md").read_text()
    assert "tilt_deg search widened from [0.2, 30] to [0.2, 90]" in text
