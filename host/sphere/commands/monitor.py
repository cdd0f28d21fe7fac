"""`sphere monitor --port P [--plot]`: a live view of a sphere, like a serial monitor that knows the protocol."""

from __future__ import annotations

import sys
import time

import numpy as np

from sphere import argtypes
from sphere.errors import LinkLost, SphereError
from sphere.link.clock import DeviceClock
from sphere.link.device import DeviceLink
from sphere.link.monitor import LinkMonitor
from sphere.link.port import PortError, open_port
from sphere.protocol import Echo, GetHello, Hello, RawSample, Reply

#: how often the monitor asks the device's clock with ECHO (spec §5.4; version-3 firmware)
ECHO_EVERY_S = 0.5

HELP = "live view of a sphere on a port: packets and rates, sensor flags, latest values, events, link quality"
DESCRIPTION = (
    "Reads the sphere's port and shows what arrives: packets per type and their rate, the RAW_SAMPLE "
    "sensor flags, the latest accelerometer, gyroscope, magnetometer and orientation values, the STATUS "
    "counters, events as they happen, and the link's quality (CRC errors, frames lost). On a terminal the "
    "view is redrawn in place; in a pipe it prints one summary line a second and one line per event. "
    "--plot draws live curves with matplotlib. Sends nothing but GET_HELLO when no HELLO comes by itself "
    "(a Bluetooth link). Ctrl-C stops it."
)


def add_arguments(p) -> None:
    p.add_argument("--port", required=True, help="the sphere's serial port (/dev/ttyUSB0, /dev/rfcomm0, /dev/sphere)")
    p.add_argument("--baud", type=argtypes.baud, default=115200, help="baud rate (default 115200, the sphere's)")
    p.add_argument("--seconds", type=argtypes.seconds, default=None, help="stop after this long (default: until Ctrl-C)")
    p.add_argument("--events", type=argtypes.at_least_one, default=None, metavar="N",
                   help="stop after N events (taps, free falls): e.g. to try a tap setting")
    p.add_argument("--plot", action="store_true", help="live curves: accelerometer, gyroscope, magnetometer, orientation")
    p.add_argument("--plot-out", metavar="PNG", type=argtypes.image_file,
                   help="write the plot's last view to this image at the end (implies --plot; works without a display)")
    p.add_argument("--refresh", type=argtypes.seconds, default=0.5, metavar="SECONDS",
                   help="how often the view is redrawn (default 0.5)")


class PlotUnusable(SphereError, ValueError):
    """--plot has no window to draw in and no --plot-out to draw into."""


class _Plot:
    """Four panels of the last ten seconds, redrawn from the monitor's history."""

    def __init__(self, out_path=None):
        import matplotlib  # optional dependency: the plot extra

        if out_path and not sys.stdout.isatty():
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # optional dependency: the plot extra

        if matplotlib.get_backend().lower() == "agg" and not out_path:  # matplotlib found no display to use
            raise PlotUnusable("--plot has no window to draw in here (no display, or no GUI toolkit for matplotlib); "
                               "add --plot-out FILE.png to write the view to an image at the end")
        self.plt = plt
        self.out_path = out_path
        self.fig, self.axes = plt.subplots(4, 1, figsize=(9, 8), sharex=True)
        self.fig.suptitle("MARG sphere — sphere monitor")
        #: a window to redraw while reading; without one (Agg) only the last view is drawn, into --plot-out
        self.live = matplotlib.get_backend().lower() != "agg"
        self.shown = False

    def update(self, mon) -> None:
        raw = np.array(mon.raw_history) if mon.raw_history else np.zeros((0, 10))
        quat = np.array(mon.quat_history) if mon.quat_history else np.zeros((0, 5))
        t_end = max(raw[-1, 0] if len(raw) else 0.0, quat[-1, 0] if len(quat) else 0.0)
        raw = raw[raw[:, 0] > t_end - 10.0] if len(raw) else raw
        quat = quat[quat[:, 0] > t_end - 10.0] if len(quat) else quat
        panels = ((raw, 1, "accel (g)", "xyz"), (raw, 4, "gyro (°/s)", "xyz"), (raw, 7, "mag (µT)", "xyz"),
                  (quat, 1, "orientation (quat)", "wxyz"))
        for ax, (data, start, label, names) in zip(self.axes, panels):
            ax.clear()
            ax.set_ylabel(label)
            for i, n in enumerate(names):
                if len(data):
                    ax.plot(data[:, 0], data[:, start + i], label=n, linewidth=1)
            ax.legend(loc="upper left", fontsize="small", ncol=len(names))
            ax.grid(alpha=0.3)
        self.axes[-1].set_xlabel("device time (s)")
        if self.live:
            if not self.shown:
                self.shown = True
                self.plt.ion()
                self.plt.show(block=False)
            self.fig.canvas.draw_idle()
            self.plt.pause(0.001)

    def close(self) -> None:
        if self.out_path:
            self.fig.savefig(self.out_path, dpi=80)
        self.plt.close(self.fig)


def run(args) -> int:
    plot = None
    if args.plot or args.plot_out:  # before the port: what it buffers meanwhile would arrive as one burst
        try:
            plot = _Plot(args.plot_out)
        except ImportError:
            print("sphere monitor: --plot needs matplotlib (pip install 'marg-sphere[plot]')", file=sys.stderr)
            return 1
        except PlotUnusable as e:
            print(f"sphere monitor: {e}", file=sys.stderr)
            return 2
    try:
        ser = open_port(args.port, args.baud, timeout_s=0.05, low_latency=True)
    except PortError as e:  # the port named is not there or not usable: a usage error
        print(f"sphere monitor: {e}", file=sys.stderr)
        return 2
    link = DeviceLink(ser, name=args.port)
    mon = LinkMonitor(link.stream.stats)
    tty = sys.stdout.isatty()
    clock = DeviceClock(args.baud)
    next_echo = 0.0
    start = time.monotonic()
    next_draw = start + args.refresh
    asked = False
    code = 0
    try:
        while args.seconds is None or time.monotonic() - start < args.seconds:
            batch = link.read()
            arrival = time.monotonic()  # the clock the ECHO round trips are timed with
            for dp in batch:
                line = mon.packet(dp, arrival)
                p = dp.packet
                if p.TYPE == RawSample.TYPE:
                    clock.note_sample(dp.t_us)
                    if clock.ready:
                        line = mon.sample_age(arrival - clock.host_s(dp.t_us), arrival) or line
                elif p.TYPE == Reply.TYPE and p.cmd_type == Echo.TYPE:
                    clock.reply(p, arrival)
                    mon.clock_uncertainty_s = clock.uncertainty_s
                elif p.TYPE == Hello.TYPE and p.seq == 0:
                    clock.restart()  # the device restarted: its clock too (spec §3)
                if line and not tty:
                    print(line, flush=True)
            if args.events is not None and mon.counts["EVENT"] >= args.events and (
                    mon.hello is not None or time.monotonic() - start > 2.0):
                break
            now = time.monotonic()
            if mon.hello is not None and mon.hello.protocol_version >= 3 and now >= next_echo:
                next_echo = now + ECHO_EVERY_S  # the device's clock on ours (spec §5.4): each sample's age
                clock.echo(lambda: link.send(Echo()), time.monotonic)
            if mon.hello is None and not asked:
                link.send(GetHello())  # the version and sensors (a USB Nano also sends HELLO when the open resets it)
                asked = True
            if now >= next_draw:
                next_draw = now + args.refresh
                if tty:
                    sys.stdout.write("\x1b[H\x1b[J" + "\n".join(mon.lines(now)) + "\n")
                    sys.stdout.flush()
                elif now - start >= 1.0:
                    print(f"{now - start:6.1f} s  {mon.summary(now)}", flush=True)
                    next_draw = now + max(args.refresh, 1.0)
                if plot is not None and plot.live:
                    plot.update(mon)
    except LinkLost as e:
        print(f"sphere monitor: {e}", file=sys.stderr)
        code = 1
    except KeyboardInterrupt:
        pass
    finally:
        stopped = time.monotonic()  # the rates are of the time it read, not of the plot's last drawing
        ser.close()
        if plot is not None:
            plot.update(mon)
            plot.close()
    if not tty:
        print("\n".join(mon.lines(stopped)))
    if not mon.counts:
        got = link.stream.stats.bytes_in
        print(f"sphere monitor: none of the {got} bytes from {args.port} was a sphere frame: another device, or the "
              f"wrong baud rate (the sphere sends 115200 8N1)" if got else
              f"sphere monitor: nothing arrived from {args.port}: is the sphere on, and this its port?", file=sys.stderr)
        return code or 1
    return code
