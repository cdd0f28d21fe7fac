"""A Nano's serial bootloader on a pseudo-terminal, for testing `sphere flash` with the real avrdude.

Written from Atmel's application note AVR061 (STK500 communication protocol, version 1) and the
behaviour documented for Optiboot (answers only at its baud rate; STK_LEAVE_PROGMODE starts the
application): every command ends with CRC_EOP and is answered STK_INSYNC ... STK_OK, a command not
followed by CRC_EOP gets STK_NOSYNC. The baud rate is the one the client set on the tty (termios): a
model at 57600 does not answer a client at 115200, as a real UART would garble the bytes.

After STK_LEAVE_PROGMODE the "application" runs: it sends the HELLO frame given (the spec's golden
vector) every ``hello_period_s``.
"""

from __future__ import annotations

import os
import select
import termios
import threading
import time
import tty

STK_OK, STK_FAILED, STK_NOSYNC, STK_INSYNC, CRC_EOP = 0x10, 0x11, 0x15, 0x14, 0x20
SIGNATURE_328P = bytes((0x1E, 0x95, 0x0F))  # ATmega328P datasheet §28.3 "Signature Bytes"
FLASH_BYTES = 32 * 1024


class Stk500Board:
    def __init__(self, baud: int = 115200, hello: bytes = b"", hello_period_s: float = 0.3, answers: bool = True,
                 page_write_s: float = 0.0):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.speed = getattr(termios, f"B{baud}")
        self.flash = bytearray(b"\xff" * FLASH_BYTES)
        self.written = set()  # byte addresses programmed
        self.hello, self.hello_period_s, self.answers = hello, hello_period_s, answers
        self.page_write_s = page_write_s  # a page write before the reply (ATmega328P datasheet, "SPM programming time": 3.7-4.5 ms)
        self.commands: list[int] = []
        self.app_running = False
        self._stop = threading.Event()
        self._buf = bytearray()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        os.close(self.master)
        os.close(self.slave)

    # -- the wire --------------------------------------------------------------------------------
    def _baud_matches(self) -> bool:
        attrs = termios.tcgetattr(self.slave)
        return attrs[4] == self.speed and attrs[5] == self.speed

    def _send(self, data: bytes) -> None:
        try:
            os.write(self.master, data)
        except OSError:
            pass

    def _take(self, n: int, timeout_s: float = 1.0) -> bytes | None:
        deadline = time.monotonic() + timeout_s
        while len(self._buf) < n:
            if not self._pump(deadline - time.monotonic()):
                return None
        out = bytes(self._buf[:n])
        del self._buf[:n]
        return out

    def _pump(self, timeout_s: float) -> bool:
        if timeout_s <= 0 or self._stop.is_set():
            return False
        r, _, _ = select.select([self.master], [], [], min(timeout_s, 0.05))
        if not r:
            return True
        try:
            data = os.read(self.master, 4096)
        except OSError:
            return True
        if self._baud_matches():
            self._buf += data
        return True

    def _run(self) -> None:
        next_hello = 0.0
        while not self._stop.is_set():
            if self.app_running:
                self._pump(0.05)
                self._buf.clear()
                if self.hello and time.monotonic() >= next_hello:
                    self._send(self.hello)
                    next_hello = time.monotonic() + self.hello_period_s
                continue
            if not self._buf:
                self._pump(0.05)
                continue
            cmd = self._buf.pop(0)
            self._command(cmd)

    # -- AVR061 commands -------------------------------------------------------------------------
    def _reply(self, body: bytes = b"") -> None:
        eop = self._take(1)
        if eop != bytes((CRC_EOP,)):
            self._send(bytes((STK_NOSYNC,)))
            return
        if self.answers:
            self._send(bytes((STK_INSYNC,)) + body + bytes((STK_OK,)))

    def _command(self, cmd: int) -> None:
        self.commands.append(cmd)
        if cmd == 0x30:  # STK_GET_SYNC
            self._reply()
        elif cmd == 0x41:  # STK_GET_PARAMETER: major/minor software version (Optiboot 8.0), others 3
            param = self._take(1) or b"\0"
            self._reply(bytes(({0x81: 8, 0x82: 0}.get(param[0], 3),)))
        elif cmd == 0x42:  # STK_SET_DEVICE: 20 parameter bytes
            self._take(20)
            self._reply()
        elif cmd == 0x45:  # STK_SET_DEVICE_EXT: a count, then count - 1 bytes
            n = self._take(1)
            self._take(max(n[0] - 1, 0) if n else 0)
            self._reply()
        elif cmd == 0x50:  # STK_ENTER_PROGMODE
            self._reply()
        elif cmd == 0x51:  # STK_LEAVE_PROGMODE: the bootloader jumps to the application
            self._reply()
            self.app_running = True
        elif cmd == 0x55:  # STK_LOAD_ADDRESS: word address, low byte first
            a = self._take(2) or b"\0\0"
            self.address = (a[0] | a[1] << 8) * 2
            self._reply()
        elif cmd == 0x56:  # STK_UNIVERSAL: four bytes of an ISP instruction, one byte back
            self._take(4)
            self._reply(b"\x00")
        elif cmd == 0x64:  # STK_PROG_PAGE: length (high, low), memory type, data
            hdr = self._take(3) or b"\0\0F"
            n = hdr[0] << 8 | hdr[1]
            data = self._take(n) or b""
            if hdr[2:3] == b"F":
                self.flash[self.address:self.address + n] = data
                self.written.update(range(self.address, self.address + n))
                time.sleep(self.page_write_s)
            self._reply()
        elif cmd == 0x74:  # STK_READ_PAGE
            hdr = self._take(3) or b"\0\0F"
            n = hdr[0] << 8 | hdr[1]
            self._reply(bytes(self.flash[self.address:self.address + n]) if hdr[2:3] == b"F" else b"\xff" * n)
        elif cmd == 0x75:  # STK_READ_SIGN
            self._reply(SIGNATURE_328P)
        else:  # Optiboot answers anything else with INSYNC OK after CRC_EOP
            self._reply()


def parse_intel_hex(text: str) -> dict[int, int]:
    """Byte address -> value from an Intel HEX file (record types 00 data, 01 end, 02/04 extended address)."""
    memory: dict[int, int] = {}
    base = 0
    for line in text.splitlines():
        line = line.strip()
        if not line:
            continue
        assert line[0] == ":", line
        raw = bytes.fromhex(line[1:])
        count, addr, rtype, data = raw[0], raw[1] << 8 | raw[2], raw[3], raw[4:4 + raw[0]]
        assert (sum(raw) & 0xFF) == 0, f"bad checksum: {line}"
        assert len(data) == count
        if rtype == 0:
            for i, b in enumerate(data):
                memory[base + addr + i] = b
        elif rtype == 1:
            break
        elif rtype == 2:
            base = (data[0] << 8 | data[1]) << 4
        elif rtype == 4:
            base = (data[0] << 8 | data[1]) << 16
    return memory
