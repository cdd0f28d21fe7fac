"""Opening the sphere's serial port (USB or Bluetooth SPP) with errors that say what to do.

Every port is opened **exclusively**, and never when another program already has it open: opening a
tty that a 3-D printer's host program (or a serial monitor) holds would change its settings and take
bytes from it. Before opening, :func:`holders` looks for other processes that have the device open
(``/proc/PID/fd``); the port is then opened with pyserial's ``exclusive`` (flock) and marked
``TIOCEXCL`` so that nobody else can open it while we hold it.
"""

from __future__ import annotations

import os
import stat

import serial

from sphere.errors import SphereError

DEFAULT_BAUD = 115200
MAX_BAUD = 4_000_000  # well above anything the sphere's UART or an SPP module does
#: termios ``c_cflag`` bit CMSPAR (Linux asm-generic/termbits.h, 010000000000; Python's termios lacks it).
#: Mark/space parity only means something together with PARENB, so CMSPAR without PARENB changes nothing on
#: any serial line; on a pseudo-terminal it is the low-latency request (:func:`request_low_latency`).
CMSPAR = 0o10000000000


class PortError(SphereError):
    """The port could not be opened or was lost; the message says what to do."""


class PortBusy(PortError):
    """Another program has the port open: it is left alone (neither opened nor read)."""


def check_baud(baud) -> str | None:
    """Why ``baud`` cannot be a serial baud rate, or None."""
    if not isinstance(baud, int) or isinstance(baud, bool) or not 50 <= baud <= MAX_BAUD:
        return f"baud rate {baud!r} is not a serial baud rate (50 … {MAX_BAUD:,}; the sphere uses {DEFAULT_BAUD})"
    return None


#: the terminal devices of Linux's major 5 (devices.txt): never the sphere's port
TERMINALS = {(5, 0): "the terminal this runs in", (5, 1): "the system console",
             (5, 2): "the pseudo-terminal multiplexer"}


def port_problem(port: str) -> str | None:
    """Why ``port`` cannot be a serial port although it exists (a folder, a file, /dev/null), or None (also
    for a port that does not exist yet: it may be plugged in)."""
    try:
        st = os.stat(port)
    except OSError:
        return None
    hint = "name the sphere's port, e.g. /dev/ttyUSB0 (`python3 -m serial.tools.list_ports` lists them)"
    if stat.S_ISDIR(st.st_mode):
        return f"{port} is a folder, not a serial port: {hint}"
    if not stat.S_ISCHR(st.st_mode):
        return f"{port} is not a serial port (not a character device): {hint}"
    if (os.major(st.st_rdev), os.minor(st.st_rdev)) in TERMINALS:  # opened, it would be the user's own terminal,
        # set raw at the sphere's rate and written frames (left so after exit: a shell that echoes nothing)
        return f"{port} is {TERMINALS[os.major(st.st_rdev), os.minor(st.st_rdev)]}, not a serial port: {hint}"
    try:  # a character device of another kind (/dev/null, /dev/zero: class mem); pseudo-terminals have no entry
        subsystem = os.path.basename(os.path.realpath(f"/sys/dev/char/{os.major(st.st_rdev)}:{os.minor(st.st_rdev)}/subsystem"))
    except (OSError, ValueError):
        return None
    if os.path.exists(f"/sys/dev/char/{os.major(st.st_rdev)}:{os.minor(st.st_rdev)}") and subsystem != "tty":
        return f"{port} is not a serial port (a {subsystem} device): {hint}"
    return None


def _hint(text: str) -> str:
    if "No such file" in text or "FileNotFound" in text:
        return "is the sphere plugged in (or paired)? list ports with `python3 -m serial.tools.list_ports`"
    if "Permission denied" in text:
        return ("install host/packaging/70-sphere-mouse.rules (it gives the sphere's port to whoever is logged in), "
                "or add yourself to the group that owns the port (usually `dialout`), then log in again")
    if "busy" in text.lower() or "resource temporarily unavailable" in text.lower() or "lock" in text.lower():
        return "another program holds the port (a serial monitor, ModemManager?); close it"
    return "check the port name"


def _parent(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[1])
    except (OSError, ValueError, IndexError):
        return 0


def _within(pid: int, roots) -> bool:
    """True when ``pid`` is one of ``roots`` or a descendant of one (the virtual board we started holds its pty)."""
    for _ in range(64):
        if pid in roots:
            return True
        if pid <= 1:
            return False
        pid = _parent(pid)
    return False


def _pty_index(path: str) -> int | None:
    """N for a pty slave /dev/pts/N, else None."""
    real = os.path.realpath(path)
    if real.startswith("/dev/pts/") and real[9:].isdigit():
        return int(real[9:])
    return None


def _holds_master(pid: str, index: int) -> bool:
    """True when process ``pid`` holds the master side of pty ``index``: it is the device end of that pty (the
    virtual board, a simulated device), not a program using the port."""
    fd_dir = f"/proc/{pid}/fd"
    try:
        fds = os.listdir(fd_dir)
    except OSError:
        return False
    for fd in fds:
        try:
            if os.path.basename(os.readlink(f"{fd_dir}/{fd}")) != "ptmx":
                continue
            with open(f"/proc/{pid}/fdinfo/{fd}") as f:
                for line in f:
                    if line.startswith("tty-index:") and int(line.split()[1]) == index:
                        return True
        except (OSError, ValueError):
            continue
    return False


def holders(path: str, allow_pids=()) -> list[tuple[int, str]]:
    """(pid, program name) of other programs that have the device ``path`` open, as far as /proc shows
    them (processes of other users are not visible without privileges; TIOCEXCL still stops us there).
    ``allow_pids`` and their descendants do not count (the virtual board we started), nor does a process that
    holds the master side of the same pty (it is the device: the virtual board). Empty where /proc does not
    exist."""
    try:
        rdev = os.stat(path).st_rdev
    except OSError:
        return []
    if not rdev or not os.path.isdir("/proc"):
        return []
    me = os.getpid()
    pty_index = _pty_index(path)
    out = []
    for name in os.listdir("/proc"):
        if not name.isdigit() or int(name) == me:
            continue
        fd_dir = f"/proc/{name}/fd"
        try:
            fds = os.listdir(fd_dir)
        except OSError:
            continue
        for fd in fds:
            try:
                st = os.stat(f"{fd_dir}/{fd}")
            except OSError:
                continue
            if st.st_rdev == rdev and (st.st_mode & 0o170000) == 0o020000:  # the same character device
                try:
                    with open(f"/proc/{name}/comm") as f:
                        comm = f.read().strip()
                except OSError:
                    comm = "?"
                device_end = pty_index is not None and _holds_master(name, pty_index)
                if not device_end and not (allow_pids and _within(int(name), set(allow_pids))):
                    out.append((int(name), comm))
                break
    return out


def _set_exclusive(ser) -> None:
    """TIOCEXCL: further opens of this tty fail with EBUSY (except for root) while we hold it."""
    try:
        import fcntl  # POSIX only (the port module also runs on Windows, through pyserial)
        import termios  # POSIX only (the port module also runs on Windows, through pyserial)

        fcntl.ioctl(ser.fileno(), termios.TIOCEXCL)
    except (ImportError, AttributeError, OSError, ValueError):
        pass


def request_low_latency(ser) -> str | None:
    """Ask the port to pass received bytes on at once instead of holding them; None when asked, else why
    not (one line, for the log).

    - A USB-serial or UART port: the ``ASYNC_LOW_LATENCY`` flag (TIOCSSERIAL, pyserial's
      ``set_low_latency_mode``). The FT232R's driver (ftdi_sio) then sets the chip's latency timer to 1 ms
      instead of 16 ms; a driver without the flag (ch341: the CH340 has no such timer; Bluetooth rfcomm)
      refuses it, which costs nothing there.
    - A pseudo-terminal (the virtual board, ``sphere sim --pty``) has no driver to ask: the request is
      written into the pty's termios as :data:`CMSPAR` without PARENB, which the kernel keeps and the
      device end reads with ``tcgetattr`` on its master (hardware/sim/README.md, "The host's requests").
      Setting the baud rate rewrites the termios, so call this again after it.
    """
    try:
        ser.set_low_latency_mode(True)
        return None
    except AttributeError:  # pyserial offers it on Linux only
        return f"{ser.port}: this platform has no low-latency request; bytes may wait for the adapter's timer"
    except (ValueError, OSError) as e:
        why = str(e)
    if _pty_index(ser.port) is not None:
        try:
            import termios  # POSIX only (the port module also runs on Windows, through pyserial)

            attrs = termios.tcgetattr(ser.fileno())
            attrs[2] |= CMSPAR
            termios.tcsetattr(ser.fileno(), termios.TCSANOW, attrs)
            return None
        except (ImportError, OSError, termios.error) as e:
            why = str(e)
    return (f"{ser.port}: the driver offers no low-latency mode ({why}); bytes may wait for the adapter's own "
            "timer (an FTDI adapter: the udev rule in host/packaging sets its latency_timer to 1 ms)")


def switchable_port(port: str) -> bool:
    """True when ``port`` is a USB-serial adapter (its tty's device sits on the USB bus) or a pseudo-terminal (the
    virtual board): a link whose rate the host sets. False for a Bluetooth rfcomm port (the module's own UART runs at
    the rate it is set to) and anything unknown."""
    if _pty_index(port) is not None:
        return True
    name = os.path.basename(os.path.realpath(port))
    try:
        device = os.path.realpath(f"/sys/class/tty/{name}/device")
    except OSError:
        return False
    return "/usb" in device and os.path.exists(f"/sys/class/tty/{name}/device")


def open_port(port: str, baud: int = DEFAULT_BAUD, timeout_s: float = 0.1, *, reset_on_open: bool = True,
              write_timeout_s: float | None = None, exclusive: bool = True, allow_pids=(),
              low_latency: bool = False) -> serial.Serial:
    """Open a port for reading frames: 8N1, no flow control, a short read timeout, exclusively.

    ``reset_on_open=False`` holds DTR low while opening, so a USB Nano is not reset where the driver
    allows it (the Linux tty layer raises DTR on every open, which resets a Nano whose auto-reset
    capacitor is fitted); Bluetooth SPP ports have no DTR to pulse. ``low_latency``: ask the driver to
    pass bytes on at once (:func:`request_low_latency`); why it could not is in ``ser.low_latency_problem``
    (None when asked). Raises :class:`PortBusy` when another
    program has the port open (it is not opened at all then), :class:`PortError` otherwise.
    """
    problem = check_baud(baud)
    if problem:
        raise PortError(f"cannot open {port}: {problem}")
    problem = port_problem(port)
    if problem:
        raise PortError(problem)
    if exclusive:
        held = holders(port, allow_pids)
        if held:
            who = ", ".join(f"{comm} (pid {pid})" for pid, comm in held)
            raise PortBusy(f"{port} is open in another program: {who}; it is left alone")
    ser = serial.Serial()
    ser.port = port
    try:
        ser.baudrate = baud
    except ValueError as e:
        raise PortError(f"cannot open {port} at {baud} baud: {e}") from None
    ser.timeout = timeout_s
    ser.write_timeout = write_timeout_s
    if exclusive:
        ser.exclusive = True  # flock: a second sphere program (sphere capture beside sphere-mouse) is refused
    if not reset_on_open:
        ser.dtr = False  # applied at open
    try:
        ser.open()
    except (serial.SerialException, OSError, ValueError, OverflowError) as e:
        text = str(e)
        if exclusive and ("lock" in text.lower() or "busy" in text.lower()):
            raise PortBusy(f"{port} is held by another program ({text}); close it") from None
        raise PortError(f"cannot open {port}: {text}; {_hint(text)}") from None
    if exclusive:
        _set_exclusive(ser)
    ser.low_latency_problem = request_low_latency(ser) if low_latency else None
    return ser
