"""The notes a command prints for its readers' warnings (trialformat.cliargs.reader_notes)."""

import warnings

from trialformat.cliargs import reader_notes


def _caught(*warns):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for message, category in warns:
            warnings.warn(message, category)
    return caught


def test_one_note_per_file_for_the_same_note_on_several_recordings():
    lines = reader_notes(_caught(("a.mat:z_df: keys absent, filled", UserWarning),
                                 ("a.mat:z_pf: keys absent, filled", UserWarning),
                                 ("b.mat:z_df: keys absent, filled", UserWarning),
                                 ("a.mat:z_pf: few segments", UserWarning)))
    assert lines == ["note: a.mat (z_df, z_pf): keys absent, filled",
                     "note: b.mat:z_df: keys absent, filled",
                     "note: a.mat:z_pf: few segments"]


def test_libraries_deprecations_are_not_the_users_and_control_characters_are_escaped():
    class Pandas4Warning(DeprecationWarning):
        pass
    lines = reader_notes(_caught(("option is deprecated", Pandas4Warning),
                                 ("later", FutureWarning),
                                 ("plain \x1b[31mred", UserWarning)))
    assert len(lines) == 1 and "\x1b" not in lines[0] and lines[0].startswith("note: plain")
