"""sphere.link.baud.switch_baud, the host's side of SET_BAUD (protocol/spec.md §5.4) that sphere-mouse and
`sphere bench baud-switch` both run, against a sphere that follows §5.4 byte by byte on a simulated clock: bytes whose
two ends run at different rates arrive garbled (as on the virtual board), the sphere answers every intact command at
its rate and falls back to 115200 by itself 1 s after a switch nobody confirmed."""

from __future__ import annotations

from sphere.link.baud import CONFIRM_S, ECHO_AGAIN_S, switch_baud
from sphere.link.device import DeviceLink
from sphere.protocol import Echo, PacketStream, Reply, SetBaud, encode_frame
from sphere.protocol.packets import DEFAULT_BAUD

TICK_S = 0.002  # simulated time per read of the port


def garble(data: bytes) -> bytes:
    return bytes((b * 37 + 11) & 0xFF for b in data)


class Sphere:
    """The device end. ``late_writes``: how many of the host's writes after SET_BAUD's REPLY still reach it before
    its UART switched (a host that reacted within a byte time); ``mute``: it never answers at the new rate;
    ``reply_delay_s``: how long after a command its REPLY reaches the host."""

    def __init__(self, late_writes=0, mute=False, reply_delay_s=0.0, refuse=False):
        self.t = 0.0
        self.baud = DEFAULT_BAUD
        self.late_writes = late_writes
        self.mute, self.reply_delay_s, self.refuse = mute, reply_delay_s, refuse
        self.switch_to = None  # switched, but until the late writes are in
        self.switched_at = None
        self.fell_back_at = None
        self.stream = PacketStream("host")
        self.out: list[tuple[float, bytes, int]] = []  # (due, bytes, rate they are sent at)
        self.seq = 0
        self.echoes_taken = 0

    def receive(self, data: bytes, host_baud: int) -> None:
        if self.switch_to is not None:
            if self.late_writes:
                self.late_writes -= 1
            else:
                self.baud, self.switch_to, self.switched_at = self.switch_to, None, self.t
        if host_baud != self.baud:
            data = garble(data)
        for dp in self.stream.feed(data):
            self.command(dp.packet)

    def command(self, p) -> None:
        if self.switched_at is not None and self.baud != DEFAULT_BAUD and self.mute:
            return
        self.switched_at = None  # an intact frame at the new rate: confirmed
        if p.TYPE == SetBaud.TYPE:
            result = 2 if self.refuse else 0
            self._reply(p, result)
            if not result:
                self.switch_to = p.baud
                if not self.late_writes:
                    self.baud, self.switch_to, self.switched_at = p.baud, None, self.t
        elif p.TYPE == Echo.TYPE:
            self.echoes_taken += 1
            self._reply(p, 0, data=b"\0\0\0\0")

    def _reply(self, p, result, data=b"") -> None:
        frame = encode_frame(Reply(cmd_seq=p.seq, cmd_type=p.TYPE, result=result, data=data), self.seq)
        self.seq = (self.seq + 1) & 0xFF
        self.out.append((self.t + self.reply_delay_s, frame, self.baud))

    def advance(self, dt: float) -> None:
        self.t += dt
        if self.switched_at is not None and self.baud != DEFAULT_BAUD and self.t - self.switched_at >= 1.0:
            self.baud, self.switched_at, self.fell_back_at = DEFAULT_BAUD, None, self.t  # rule 3


class Port:
    """The host's serial port to the Sphere: what it writes arrives at once; a read advances the clock."""

    def __init__(self, sphere: Sphere):
        self.sphere = sphere
        self.baudrate = DEFAULT_BAUD
        self.rates: list[tuple[float, int]] = []

    @property
    def in_waiting(self) -> int:
        return 0

    def write(self, data: bytes) -> int:
        self.sphere.receive(data, self.baudrate)
        return len(data)

    def read(self, n: int = 1) -> bytes:
        s = self.sphere
        s.advance(TICK_S)
        due = [item for item in s.out if item[0] <= s.t]
        s.out = [item for item in s.out if item[0] > s.t]
        return b"".join(frame if rate == self.baudrate else garble(frame) for _, frame, rate in due)

    def port_to(self, baud: int) -> None:
        self.baudrate = baud
        self.rates.append((self.sphere.t, baud))


def run(sphere: Sphere):
    port = Port(sphere)
    link = DeviceLink(port, PacketStream("device"))
    done = switch_baud(link, 1000000, port.port_to, now=lambda: sphere.t)
    return done, port


def test_an_answered_echo_confirms_at_once():
    sphere = Sphere()
    done, port = run(sphere)
    assert done.ok and done.baud == 1000000 and done.echoes == 1 and port.baudrate == 1000000
    assert [baud for _, baud in port.rates] == [1000000]


def test_an_echo_garbled_before_the_sphere_switched_is_sent_again_after_a_delimiter():
    """The first ECHO reaches the sphere while its UART still runs at 115200: garbled, and its garbled delimiter ends
    nothing. The next ECHO's 0x00 at the right rate ends that garbage, so the second ECHO confirms the switch."""
    sphere = Sphere(late_writes=1)
    done, port = run(sphere)
    assert done.ok and done.echoes == 2 and port.baudrate == 1000000, done
    assert ECHO_AGAIN_S <= done.confirm_s < ECHO_AGAIN_S + 0.02
    assert sphere.echoes_taken == 1 and sphere.stream.stats.framing_errors >= 1  # the garbled one, dropped


def test_a_reply_to_an_earlier_echo_confirms():
    """A slow answer (a loaded machine, a 16 ms latency timer): the REPLY to the first ECHO arrives after the second
    ECHO went out; it is as good as one to the second."""
    sphere = Sphere(reply_delay_s=ECHO_AGAIN_S * 1.5)
    done, _ = run(sphere)
    assert done.ok and done.echoes == 2, done
    assert done.confirm_s < ECHO_AGAIN_S * 2


def test_no_answer_sends_the_port_back_to_115200_before_the_sphere_falls_back():
    """Spec §5.4 rule 5: no REPLY within 0.5 s, the port back to 115200; the sphere comes back after its 1 s (rule 3),
    so the host is listening at 115200 by then and hears everything the sphere sends after it."""
    sphere = Sphere(mute=True)
    done, port = run(sphere)
    assert not done.ok and done.why == "no answer" and done.baud == DEFAULT_BAUD and port.baudrate == DEFAULT_BAUD
    (t_up, up), (t_back, back) = port.rates
    assert (up, back) == (1000000, DEFAULT_BAUD)
    assert CONFIRM_S <= t_back - t_up < CONFIRM_S + 0.01
    assert done.echoes == round(CONFIRM_S / ECHO_AGAIN_S)
    while sphere.fell_back_at is None:
        sphere.advance(TICK_S)
    assert sphere.fell_back_at - t_back > 0.45  # the host was back half a second before the sphere


def test_a_refused_rate_leaves_the_port_alone():
    sphere = Sphere(refuse=True)
    done, port = run(sphere)
    assert not done.ok and done.why == "result 2" and done.echoes == 0 and port.rates == []
    assert sphere.baud == DEFAULT_BAUD
