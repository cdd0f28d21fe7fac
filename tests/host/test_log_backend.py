"""The log backend sums moves once a second and prints clicks as they happen, in order."""

import io

from sphere.daemon.backends.log import LogBackend


def test_moves_are_summed_per_second_and_clicks_keep_their_place():
    out = io.StringIO()
    now = [0.0]
    b = LogBackend(out, clock=lambda: now[0])
    for i in range(250):  # 200 Hz for 1.25 s, 2 px right, 1 px up each
        now[0] = i / 200
        b.move(2, -1)
    b.click("left")
    now[0] = 2.0
    b.move(-5, 0)
    b.close()
    lines = out.getvalue().splitlines()
    assert lines == [
        "move +402 -201 px in 201 steps; at +402 -201 from the start",  # the first second (0 … 1.0 s inclusive)
        "move +98 -49 px in 49 steps; at +500 -250 from the start",
        "click left",
        "move -5 +0 px in 1 steps; at +495 -250 from the start",
    ]


def test_nothing_printed_without_moves():
    out = io.StringIO()
    b = LogBackend(out)
    b.close()
    assert out.getvalue() == ""
