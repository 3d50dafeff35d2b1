"""Running the CLI in-process from the tests."""

from __future__ import annotations

from bench.cli import main


def run(capsys, *argv):
    """``hikbench ARGV`` (each argument converted to str); returns (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_user_error(code, err, *fragments):
    """A user mistake: exit code 2, one line on stderr holding every fragment, no
    traceback, no warning."""
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err and "Warning" not in err
    for f in fragments:
        assert f in err, err
