"""What the command-line tests share: the check that an error is one line (the fixture ``no_data``, a run without
a data root, is in ``conftest.py``)."""


def one_error_line(capsys, *words) -> str:
    """The captured standard error is one line, ``polyjax: error: ...``, holding every one of ``words``."""
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("polyjax: error:"), err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]
