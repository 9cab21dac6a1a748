"""Outputs never undo a user's protection: a read-only --out folder, or a folder a
report would be written in that is read-only, is refused up front naming it."""

import tempfile

import pytest

from trialformat import logs
from trialformat.errors import OutputError


@pytest.fixture
def read_only(tmp_path):
    folder = tmp_path / "archive"
    folder.mkdir()
    folder.chmod(0o555)
    yield folder
    folder.chmod(0o755)


def test_a_read_only_out_folder_is_refused_not_swapped(read_only):
    """replace_dir moved a read-only empty folder aside and put a writable one there."""
    with pytest.raises(OutputError, match=r"--out .*archive: the folder is read-only "
                       r"\(mode 555\); it is left as it is"):
        logs.check_report_out(read_only)
    assert read_only.stat().st_mode & 0o777 == 0o555


def test_a_path_in_a_read_only_folder_is_refused_naming_the_folder(read_only):
    for check in (logs.check_report_out, logs.check_trial_out):
        with pytest.raises(OutputError, match=r"cannot write in .*archive \(read-only, "
                           r"mode 555\)"):
            check(read_only / "new")


def test_an_unwritable_target_is_named_not_its_temporary_file(tmp_path, monkeypatch):
    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied", str(tmp_path / ".r.json.abc.tmp"))
    monkeypatch.setattr(tempfile, "mkstemp", denied)
    with pytest.raises(OutputError) as info:
        logs.atomic_write(tmp_path / "r.json", lambda fh: fh.write(b"{}"))
    assert "r.json: cannot write in" in str(info.value) and ".tmp" not in str(info.value)

