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


def test_a_message_of_several_problems_keeps_its_lines():
    """'1 problem(s):\\n  - ...' was printed with a literal backslash-n."""
    from trialformat.csvtable import printable
    text = "plant.fmu breaks the contract, 2 problem(s):\n  - a\x1b[2J\n  - b"
    assert printable(text, lines=True) == ("plant.fmu breaks the contract, 2 problem(s):"
                                           "\n  - a\\x1b[2J\n  - b")
    assert "\n" not in printable(text)


def test_cli_error_of_several_problems_prints_one_per_line(monkeypatch, capsys):
    from orchestrator import cli

    def fails(args):
        raise ValueError("x.fmu breaks the plant contract, 2 problem(s):\n  - p1\n  - p2")

    parser = cli.build_parser()
    real = parser.parse_args
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    monkeypatch.setattr(parser, "parse_args",
                        lambda argv=None: real(argv).__class__(**{**vars(real(argv)),
                                                                  "func": fails}))
    assert cli.main(["simulate", "--out", "unused"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[-3:] == ["armimp simulate: error: x.fmu breaks the plant contract, "
                        "2 problem(s):", "  - p1", "  - p2"]


def test_the_same_note_on_many_files_is_said_once_with_the_count():
    """200 files lacking one key gave 200 identical notes."""
    text = "metadata keys absent, filled from the documented 1-joint defaults: friction"
    lines = reader_notes(_caught(*[(f"r{i}.csv: {text}", UserWarning) for i in range(200)],
                                 ("r7.csv: few segments", UserWarning),
                                 ("a.csv: once", UserWarning), ("b.csv: once", UserWarning)))
    assert lines == [f"note: 200 files (r0.csv, r1.csv, r2.csv, ...): {text}",
                     "note: r7.csv: few segments", "note: a.csv: once", "note: b.csv: once"]

