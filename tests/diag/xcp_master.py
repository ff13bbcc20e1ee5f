#!/usr/bin/env python
"""pyxcp as the XCP master of the TCU on vcan0, driven by the A2L file `ddct diag a2l` writes
(parsed with pya2ldb, pyxcp's A2L companion): connect, optionally download calibrations by
name, then measure by synchronous DAQ on the 10 ms event for a while and write every sample
(pyxcp's own decoding, with the slave's timestamps) as JSON.

    python xcp_master.py --a2l tcu.a2l --seconds 10 --out daq.json \
        --measure Clutch1TempEst Clutch1TorqueRef [--download control_clutch_kp_per_s=20]

Run as its own process: pyxcp keeps a global application object.
"""

from __future__ import annotations

import argparse
import json
import struct
import sys
import time
from pathlib import Path


def a2l_objects(path: Path) -> dict[str, dict]:
    """Every MEASUREMENT and CHARACTERISTIC of the A2L: name -> address, type, limits, kind."""
    import pya2l
    from pya2l import model

    session = pya2l.import_a2l(str(path), in_memory=True, progress_bar=False, loglevel="WARN")
    out = {}
    for m in session.query(model.Measurement).all():
        out[m.name] = {"kind": "measurement", "address": m.ecu_address.address, "type": m.datatype,
                       "lower": m.lowerLimit, "upper": m.upperLimit}
    for c in session.query(model.Characteristic).all():
        out[c.name] = {"kind": "characteristic", "address": c.address, "lower": c.lowerLimit,
                       "upper": c.upperLimit}
    return out


def master(channel: str):
    """pyxcp's application and its bus. The bus is ours, handed to pyxcp as a user-supplied
    interface, because pyxcp then also filters the slave's id in software. A bus pyxcp opens
    itself accepts every frame that reaches the socket between its bind and its kernel filter, and
    pyxcp feeds such a frame (say an ENG_Status, first byte < 0xFC) to the DAQ policy as a DAQ
    packet; before the DAQ lists are set up its decoder is null and the process dies with SIGSEGV
    (a fresh-clone CI run: `xcp_master.py --download` exited -11)."""
    import can
    from ddct_can.dbc import frame_id

    from pyxcp.config import create_application_from_config, set_application
    from pyxcp.master import Master

    bus = can.Bus(interface="socketcan", channel=channel)
    app = create_application_from_config({
        "Transport": {"CAN": {
            "interface": "socketcan", "channel": channel, "can_id_master": frame_id("TCU_XcpCro"),
            "can_id_slave": frame_id("TCU_XcpDto"), "max_dlc_required": True, "padding_value": 0,
        }},
    })
    app.transport.layer = "CAN"
    set_application(app)
    return app, Master, bus


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a2l", type=Path, required=True)
    ap.add_argument("--channel", default="vcan0")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--measure", nargs="+", default=["Clutch1TempEst", "Clutch1TorqueRef"])
    ap.add_argument("--download", nargs="*", default=[], help="NAME=VALUE calibrations to write first")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--list", action="store_true", help="only write the A2L's objects as JSON")
    args = ap.parse_args(argv)

    objects = a2l_objects(args.a2l)
    if args.list:
        args.out.write_text(json.dumps(objects))
        return 0
    from pyxcp.daq_stim import DaqList, DaqOnlinePolicy

    class Collect(DaqOnlinePolicy):
        def __init__(self, lists):
            super().__init__(lists)
            self.samples = []

        def initialize(self):
            pass

        def finalize(self):
            pass

        def on_daq_list(self, daq_list, timestamp0, timestamp1, payload):
            self.samples.append((time.monotonic(), timestamp0, timestamp1, list(payload)))

    measurements = [(n, objects[n]["address"], 0, "F32") for n in args.measure]
    daq = Collect([DaqList(name="tcu_10ms", event_num=0, stim=False, enable_timestamps=True,
                           measurements=measurements, priority=0, prescaler=1)])
    app, Master, bus = master(args.channel)
    result = {"measure": args.measure, "downloads": {}, "uploads": {}}
    with bus, Master("can", config=app, policy=daq, transport_layer_interface=bus) as x:
        x.connect()
        for item in args.download:
            name, value = item.split("=", 1)
            addr = objects[name]["address"]
            before = struct.unpack("<f", x.shortUpload(4, addr))[0]
            x.setMta(addr)
            x.download(struct.pack("<f", float(value)))
            after = struct.unpack("<f", x.shortUpload(4, addr))[0]
            result["downloads"][name] = {"before": before, "after": after, "at": time.monotonic()}
        for n in args.measure:
            result["uploads"][n] = struct.unpack("<f", x.shortUpload(4, objects[n]["address"]))[0]
        daq.setup()
        t0 = time.monotonic()
        daq.start()
        time.sleep(args.seconds)
        daq.stop()
        t1 = time.monotonic()
        x.disconnect()
    result["daq_start"], result["daq_stop"] = t0, t1
    result["samples"] = daq.samples
    args.out.write_text(json.dumps(result))
    print(f"{len(daq.samples)} DAQ samples in {t1 - t0:.2f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
