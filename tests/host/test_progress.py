"""Progress bars (tqdm) on long commands: shown on a terminal (or with SPHERE_PROGRESS=1), never in pipes."""

from sphere import progress


def test_bar_only_when_asked_or_on_a_terminal(monkeypatch, capsys):
    monkeypatch.setenv("SPHERE_PROGRESS", "1")
    assert list(progress.bar(range(3), desc="work")) == [0, 1, 2]
    assert "work" in capsys.readouterr().err
    monkeypatch.setenv("SPHERE_PROGRESS", "0")
    list(progress.bar(range(3), desc="work"))
    assert capsys.readouterr().err == ""
    monkeypatch.delenv("SPHERE_PROGRESS")
    list(progress.bar(range(3), desc="work"))  # pytest's stderr is not a terminal
    assert capsys.readouterr().err == ""

