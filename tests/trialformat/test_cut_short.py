"""A CSV whose last row was cut short (lab session tester): the refusal says it is the last
row, that the file looks cut short, and what to do."""

import numpy as np
import pytest

import trialformat as tf
from trialformat import TrialFormatError


def _written(tmp_path, n=1500):
    rng = np.random.default_rng(0)
    sig = {s: rng.standard_normal((n, 1)) for s in tf.SIGNALS}
    trial = tf.Trial(meta=tf.default_metadata(1), t=np.arange(n) / 1000.0, **sig)
    return tf.write_trial(tmp_path / "cut", trial)


def test_truncated_last_row_is_said_to_be_the_last_and_the_file_cut_short(tmp_path):
    path = _written(tmp_path)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-1] + [",".join(lines[-1].split(",")[:3])]))
    with pytest.raises(TrialFormatError) as info:
        tf.read_trial(path, min_samples=1000)
    text = str(info.value)
    assert "data row 1500 has 3 fields, the header has 5: it is the last row" in text
    assert "looks cut short" in text and "delete that row, or export the file again" in text


def test_short_row_inside_the_file_is_not_called_the_last(tmp_path):
    path = _written(tmp_path)
    lines = path.read_text().splitlines()
    lines[10] = ",".join(lines[10].split(",")[:3])
    path.write_text("\n".join(lines) + "\n\n")  # trailing blank lines do not count as rows
    with pytest.raises(TrialFormatError, match="data row 10 has 3 fields, the header has "
                       r"5$"):
        tf.read_trial(path, min_samples=1000)
    path = _written(tmp_path)  # a cut last row then blank lines: still the last row
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-1] + [lines[-1][:5]]) + "\n\n")
    with pytest.raises(TrialFormatError, match="has 1 fields, the header has 5: it is the "
                       "last row"):
        tf.read_trial(path, min_samples=1000)
