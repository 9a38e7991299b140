#!/usr/bin/python3
"""A Modbus analog I/O module in front of a simulated PVC gel actuator, served by pymodbus.

Register map (zero-based, as on the wire; the same as config/pvcgeld-modbus.toml):
  input 0-1   displacement, int32, high word first, 0.001 um/count (sensor noise 0.05 um)
  input 2     amplifier output voltage monitor, uint16, 0.1 V/count
  input 3     amplifier output current monitor, uint16, 0.001 mA/count
  holding 10  amplifier control input, uint16, 0.001 V/count (0..10 V), amplifier gain 100 V/V

Plant (the paper's identified model, eq. 11 and Table II n = 2): x = 0.1270 u + 1.3057e-5 u^3
(u in V) through G(s) = (1.15 s + 1.03) / (s^2 + 17.11 s + 8.76), output in um. The plant is
advanced exactly (zero-order hold, partial fractions) over the wall-clock time between requests,
so it needs no timer thread.

Test hooks: --journal FILE logs input-register reads ("R 4 addr count") and holding-register
writes ("W addr value...") in order, flushed per line (pymodbus' read-back of a written register
for its reply is not logged); SIGUSR1 toggles a response delay of --slow-ms before every read; SIGUSR2 toggles refusing
writes to the amplifier register with an exception (reads still answered: a module whose output
stage failed); --unit sets the one unit id
served (other ids get a gateway exception over TCP, silence over RTU).
Run with /usr/bin/python3 (Debian's python3-pymodbus 3.0).
"""
import argparse
import logging
import asyncio
import ctypes
import math
import os
import random
import signal
import sys
import time

from pymodbus.datastore import ModbusSequentialDataBlock, ModbusServerContext, ModbusSlaveContext
from pymodbus.server import StartAsyncSerialServer, StartAsyncTcpServer
from pymodbus.transaction import ModbusRtuFramer, ModbusSocketFramer

SENSOR_UM_PER_COUNT = 0.001
MONITOR_V_PER_COUNT = 0.1
MONITOR_MA_PER_COUNT = 0.001
AMP_INPUT_V_PER_COUNT = 0.001
AMP_GAIN = 100.0
AMP_REGISTER = 10


class Plant:
    """Hammerstein plant, advanced exactly over arbitrary time steps."""

    def __init__(self, noise_um):
        b1, b0, a1, a0 = 1.15, 1.03, 17.11, 8.76
        disc = math.sqrt(a1 * a1 - 4.0 * a0)
        self.p = [(-a1 + disc) / 2.0, (-a1 - disc) / 2.0]
        p1, p2 = self.p
        self.r = [(b1 * p1 + b0) / (p1 - p2), (b1 * p2 + b0) / (p2 - p1)]
        self.z = [0.0, 0.0]
        self.u_V = 0.0
        self.t = time.monotonic()
        self.noise_um = noise_um

    def advance(self):
        now = time.monotonic()
        dt, self.t = now - self.t, now
        x = 0.1270 * self.u_V + 1.3057e-5 * self.u_V ** 3
        for i, p in enumerate(self.p):
            e = math.exp(p * dt)
            self.z[i] = e * self.z[i] + (e - 1.0) / p * x

    def y_um(self):
        return self.r[0] * self.z[0] + self.r[1] * self.z[1] + random.gauss(0.0, self.noise_um)


class Journal:
    def __init__(self, path):
        self.f = open(path, "a", buffering=1) if path else None

    def log(self, line):
        if self.f:
            self.f.write(f"{time.monotonic():.6f} {line}\n")


class InputBlock(ModbusSequentialDataBlock):
    """Input registers computed from the plant on every read."""

    def __init__(self, plant, journal, state):
        super().__init__(0, [0] * 16)
        self.plant, self.journal, self.state = plant, journal, state

    def getValues(self, address, count=1):
        if self.state["slow"]:
            time.sleep(self.state["slow_ms"] / 1000.0)  # blocks the server, as a stalled module would
        self.journal.log(f"R 4 {address} {count}")
        self.plant.advance()
        counts = int(round(self.plant.y_um() / SENSOR_UM_PER_COUNT)) & 0xFFFFFFFF
        self.values[0], self.values[1] = counts >> 16, counts & 0xFFFF
        self.values[2] = max(0, min(65535, int(round(self.plant.u_V / MONITOR_V_PER_COUNT))))
        # A capacitive load: current ~ C du/dt is small; report a constant leakage of 0.05 mA when on.
        self.values[3] = int(round((0.05 if self.plant.u_V > 0 else 0.0) / MONITOR_MA_PER_COUNT))
        return super().getValues(address, count)


class HoldingBlock(ModbusSequentialDataBlock):
    """Holding registers; register 10 drives the amplifier."""

    def __init__(self, plant, journal):
        super().__init__(0, [0] * 16)
        self.plant, self.journal = plant, journal

    def setValues(self, address, values):
        super().setValues(address, values)
        self.journal.log(f"W {address} {' '.join(str(v) for v in values)}")
        if address <= AMP_REGISTER < address + len(values):
            self.plant.advance()  # the old voltage acted until now
            self.plant.u_V = self.values[AMP_REGISTER] * AMP_INPUT_V_PER_COUNT * AMP_GAIN


class SlaveContext(ModbusSlaveContext):
    """Refuses writes (function codes 6 and 16) that touch the amplifier register while state["refuse_writes"]."""

    def __init__(self, state, **kwargs):
        super().__init__(**kwargs)
        self.state = state

    def validate(self, fc_as_hex, address, count=1):
        if self.state["refuse_writes"] and fc_as_hex in (6, 16) and address <= AMP_REGISTER < address + count:
            return False  # answered with an exception (illegal data address)
        return super().validate(fc_as_hex, address, count)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--transport", choices=["tcp", "rtu"], default="tcp")
    ap.add_argument("--port", type=int, default=1502, help="TCP port on 127.0.0.1")
    ap.add_argument("--device", help="RTU: serial device (e.g. one end of a socat pty pair)")
    ap.add_argument("--baud", type=int, default=115200)
    ap.add_argument("--unit", type=int, default=1, help="the unit id served")
    ap.add_argument("--journal", help="append every request to this file")
    ap.add_argument("--slow-ms", type=float, default=20.0, help="delay per read while slowed (SIGUSR1 toggles)")
    ap.add_argument("--noise-um", type=float, default=0.05)
    ap.add_argument("--ready-file", help="touched once the server is about to serve")
    ap.add_argument("--realtime-priority", type=int, default=20, help="SCHED_FIFO priority if permitted; 0 = off")
    args = ap.parse_args()

    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # disconnects are normal here
    if args.realtime_priority > 0:
        # A hardware module is never descheduled by a compiler on the same machine; where
        # allowed, the stand-in runs SCHED_FIFO (below pvcgeld's loop, 80). Otherwise as is.
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.realtime_priority))
            libc = ctypes.CDLL(None, use_errno=True)
            libc.mlockall(3)  # MCL_CURRENT | MCL_FUTURE: no page reclaim stalls under memory pressure
        except (PermissionError, OSError):
            pass
    plant = Plant(args.noise_um)
    journal = Journal(args.journal)
    state = {"slow": False, "slow_ms": args.slow_ms, "refuse_writes": False}
    store = SlaveContext(state, di=ModbusSequentialDataBlock(0, [0] * 16), co=ModbusSequentialDataBlock(0, [0] * 16),
                               hr=HoldingBlock(plant, journal), ir=InputBlock(plant, journal, state), zero_mode=True)
    context = ModbusServerContext(slaves={args.unit: store}, single=False)

    def toggle_slow(*_):
        state["slow"] = not state["slow"]

    def toggle_refuse_writes(*_):
        state["refuse_writes"] = not state["refuse_writes"]

    signal.signal(signal.SIGUSR1, toggle_slow)
    signal.signal(signal.SIGUSR2, toggle_refuse_writes)
    signal.signal(signal.SIGTERM, lambda *_: os._exit(0))

    async def run():
        if args.transport == "tcp":
            server = await StartAsyncTcpServer(context=context, address=("127.0.0.1", args.port), framer=ModbusSocketFramer,
                                               allow_reuse_address=True, defer_start=True)
        else:
            server = await StartAsyncSerialServer(context=context, framer=ModbusRtuFramer, port=args.device,
                                                  baudrate=args.baud, bytesize=8, parity="N", stopbits=1,
                                                  defer_start=True)
            await server.start()
        if args.ready_file:
            open(args.ready_file, "w").close()
        await server.serve_forever()

    asyncio.run(run())


if __name__ == "__main__":
    sys.exit(main())
