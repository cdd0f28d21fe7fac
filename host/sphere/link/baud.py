"""The host's side of a baud switch (protocol/spec.md §5.4): the one procedure the daemon's serial source and
``sphere bench baud-switch`` both run.

    result = switch_baud(link, 1000000, port_to)   # port_to(baud): the host's port to that rate
    if result.ok: ...                              # the sphere talks at 1,000,000 baud and the port listens there

1. a 0x00 (ends whatever the sphere took in at another rate), then SET_BAUD at the rate in use; its REPLY;
2. the port to the new rate, then ECHO there, preceded by a 0x00; a REPLY to it is the first frame at the new rate;
3. no REPLY yet: the 0x00 and an ECHO again every :data:`ECHO_AGAIN_S`. A byte the host sends before the sphere's UART
   has switched arrives garbled (the sphere switches once the REPLY has left its UART, and a host that reacts within
   a byte time, or a virtual board lagging the wall clock, can be first): that ECHO is lost, and the garbled bytes
   (a garbled 0x00 is no delimiter) would spoil the next frame too, were it not for the 0x00 before it. A REPLY to
   any of the ECHOs confirms;
4. no REPLY to any within :data:`CONFIRM_S` of the first: the port back to 115200 (rule 5). That is half the
   sphere's own 1 s window (rule 3), so the host listens at 115200 before the sphere comes back to it and hears all
   it sends then (the sphere sent nothing in between: rule 2).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from sphere.protocol import Echo, Reply, SetBaud
from sphere.protocol.packets import DEFAULT_BAUD

#: how long the REPLY to SET_BAUD (at the rate in use) is waited for
SET_BAUD_REPLY_S = 1.0
#: spec §5.4 rule 5: no REPLY to the ECHO at the new rate within this, the port goes back to 115200
CONFIRM_S = 0.5
#: within CONFIRM_S, the ECHO is sent again this often while no REPLY came (step 3 of the module docstring)
ECHO_AGAIN_S = 0.1


@dataclass
class Switched:
    """What :func:`switch_baud` did: ``ok`` when the sphere answered at ``target``; ``baud`` is the port's rate now."""

    ok: bool
    target: int
    baud: int
    why: str = ""  # when not ok: "no reply", "result N" (SET_BAUD refused) or "no answer" (nothing at the new rate)
    echoes: int = 0  # ECHOs sent at the new rate
    confirm_s: float | None = None  # first ECHO at the new rate -> its confirming REPLY


def switch_baud(link, target: int, port_to, *, reply_s: float = SET_BAUD_REPLY_S, confirm_s: float = CONFIRM_S,
                again_s: float = ECHO_AGAIN_S, now=time.monotonic) -> Switched:
    """Move the link to ``target`` baud (spec §5.4). ``link`` is a :class:`sphere.link.device.DeviceLink` at the rate
    in use (packets read meanwhile go to its ``on_packet`` as always); ``port_to(baud)`` sets the host's port to a
    rate. SET_BAUD refused or unanswered: the port stays where it was. No answer at ``target``: the port goes back to
    115200, where the sphere comes back by itself."""
    before = getattr(link.port, "baudrate", None)
    link.send_delimiter()
    reply = link.command(SetBaud(target), timeout_s=reply_s, retries=0)
    if reply is None or not reply.ok:
        return Switched(False, target, before, "no reply" if reply is None else f"result {reply.result}")
    port_to(target)
    sent: set[int] = set()
    start = now()
    next_echo = start
    while True:
        t = now()
        if t >= next_echo:
            sent.add(link.send(Echo(), delimit_first=True))
            next_echo = t + again_s
        for dp in link.read():
            p = dp.packet
            if p.TYPE == Reply.TYPE and p.cmd_type == Echo.TYPE and p.cmd_seq in sent:
                return Switched(True, target, target, echoes=len(sent), confirm_s=now() - start)
        if now() - start >= confirm_s:
            break
    port_to(DEFAULT_BAUD)
    return Switched(False, target, DEFAULT_BAUD, "no answer", echoes=len(sent))
