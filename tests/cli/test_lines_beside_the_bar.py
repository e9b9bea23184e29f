"""A warning during a run (a refused live goal, a live client refused) is printed on a line of its
own, not into the progress bar that is showing on stderr, and the bar is drawn again after it."""

from __future__ import annotations

import sys

from cosim.errors import say
from cosim.record.system_run import progress_bar, update_bar


def test_a_line_said_while_the_bar_shows_starts_after_the_bar_is_cleared(capsys):
    bar = progress_bar(10.0)
    update_bar(bar, 4.0, 0.01, [0.0, 0.0])
    bar.refresh()
    say("cosim: warning: /goal_pose (1.00, 2.00) m at t = 4.00 s refused: in an obstacle")
    bar.close()
    err = capsys.readouterr().err
    before, after = err.split("cosim: warning: /goal_pose", 1)
    assert "40%" in before  # the bar was showing
    # The bar's line was cleared (carriage return, blanks, carriage return) before the text ...
    assert before.endswith("\r") and before.rstrip("\r").endswith(" ")
    # ... the text is one whole line, and the bar comes back below it.
    line, rest = after.split("\n", 1)
    assert line.endswith("refused: in an obstacle") and "\r" not in line
    assert rest.startswith("\r") and "40%" in rest


def test_without_a_bar_it_is_a_plain_line(capsys, monkeypatch):
    monkeypatch.delitem(sys.modules, "tqdm", raising=False)
    say("cosim: warning: live view: a client was refused")
    assert capsys.readouterr().err == "cosim: warning: live view: a client was refused\n"
