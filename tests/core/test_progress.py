"""mi_displace.core.progress: a line per stage with its time, and when it is shown."""
import re
import time

import pytest

from mi_displace.core import progress


class Stderr:
    """Captured stderr (pytest's ``capsys``) with a switchable "is a terminal" answer."""

    def __init__(self, capsys, monkeypatch):
        self.capsys, self.tty = capsys, False
        monkeypatch.setattr(progress, "_stderr_is_terminal", lambda: self.tty)

    def getvalue(self):
        self.text = getattr(self, "text", "") + self.capsys.readouterr().err
        return self.text


@pytest.fixture
def stderr(capsys, monkeypatch):
    monkeypatch.delenv(progress.ENV, raising=False)
    progress.set_enabled(None)
    yield Stderr(capsys, monkeypatch)
    progress.set_enabled(None)


def test_a_stage_prints_its_label_then_its_time_and_note(stderr):
    with progress.stage("building", enabled=True) as s:
        time.sleep(0.02)
        s.note = "12 faces"
    first, second = stderr.getvalue().splitlines()
    assert first == "[mi-displace] building ..."
    seconds = float(re.fullmatch(r"\[mi-displace\] building: (\d+\.\d\d) s \(12 faces\)", second).group(1))
    assert 0.02 <= seconds < 5


def test_nested_stages_are_indented_and_a_failed_stage_has_no_closing_line(stderr):
    with pytest.raises(KeyError):
        with progress.stage("outer", enabled=True):
            with progress.stage("inner", enabled=True):
                pass
            with progress.stage("broken", enabled=True):
                raise KeyError("x")
    lines = stderr.getvalue().splitlines()
    assert [line.split(":")[0] for line in lines] == [
        "[mi-displace] outer ...", "[mi-displace]   inner ...", "[mi-displace]   inner",
        "[mi-displace]   broken ..."]
    with progress.stage("after", enabled=True):  # depth back to 0 after the exception
        pass
    assert stderr.getvalue().splitlines()[-1].startswith("[mi-displace] after: ")


@pytest.mark.parametrize("tty, env, forced, argument, shown", [
    (False, None, None, None, False),   # default: only on a terminal
    (True, None, None, None, True),
    (True, "0", None, None, False),     # the environment overrides the terminal test
    (False, "1", None, None, True),
    (False, "1", False, None, False),   # set_enabled (--quiet) overrides the environment
    (True, None, True, False, False),   # an explicit argument overrides everything
    (False, "0", False, True, True),
])
def test_when_progress_is_shown(stderr, monkeypatch, tty, env, forced, argument, shown):
    stderr.tty = tty
    if env is not None:
        monkeypatch.setenv(progress.ENV, env)
    progress.set_enabled(forced)
    assert progress.is_enabled(argument) is shown
    with progress.stage("work", enabled=argument):
        pass
    assert (stderr.getvalue() != "") is shown
    bar = progress.bar(3, "passes", enabled=argument)
    assert bar.disable is (not shown)
    bar.close()


def test_stages_are_records_of_the_mi_displace_logger(stderr, caplog):
    """A script or notebook sees the stages through logging, even when stderr is not a
    terminal (progress off for the console), and nothing is printed twice."""
    import logging

    with caplog.at_level(logging.INFO, logger="mi_displace"):
        with progress.stage("tessellating") as s:
            s.note = "8 faces"
        progress.log("point 2/4: map_resolution=32")
    messages = [r.getMessage() for r in caplog.records if r.name == "mi_displace"]
    assert messages[0] == "tessellating ..." and re.fullmatch(r"tessellating: \d+\.\d\d s \(8 faces\)", messages[1])
    assert messages[2] == "point 2/4: map_resolution=32"
    assert stderr.getvalue() == ""          # progress off: no console line
    with caplog.at_level(logging.INFO, logger="mi_displace"):
        with progress.stage("quiet", enabled=False):
            pass
    assert not any(r.getMessage().startswith("quiet") for r in caplog.records)
