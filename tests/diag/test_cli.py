"""`ddct diag`, the tester for people without a python one, against the TCU daemon on vcan0:
DIDs by name and number, the fault memory listed with its status bits, snapshot and extended
data, clear, a calibration write behind SecurityAccess, and the kiss-point routine. Checked
against udsoncan reading the same values.
"""

from __future__ import annotations

import re
import subprocess
import time

from diag_helpers import CAL_DID, CONFIRMED, bench, uds_client, wait_until

FAULTS = """
[[faults]]
message = "DCT_Sensors"
kind = "stop"
from_s = 3.0
to_s = 3.5
"""


def diag(ddct, *args, timeout=120):
    r = subprocess.run([str(ddct), "diag", *map(str, args)], capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, f"ddct diag {' '.join(map(str, args))}: {r.stderr}"
    return r.stdout


def test_ddct_diag_reads_clears_writes_and_learns(ddct, tmp_path):
    faults = tmp_path / "faults.toml"
    faults.write_text(FAULTS)
    with bench(ddct, tmp_path, plant_args=["--faults", faults]):
        out = diag(ddct, "read-did", "--iface", "vcan0", "Version", "0xF197", "control.clutch_kp_per_s")
        assert re.search(r"0xf195 Version = \"ddct \d", out), out
        assert '0xf197 SystemName = "ddct TCU"' in out, out
        m = re.search(r"0x0200 control.clutch_kp_per_s = ([0-9.]+) 1/s", out)
        assert m, out
        with uds_client() as c:
            assert float(m.group(1)) == c.read_data_by_identifier(CAL_DID["control.clutch_kp_per_s"]) \
                .service_data.values[CAL_DID["control.clutch_kp_per_s"]]
            wait_until(lambda: c.get_dtc_by_status_mask(CONFIRMED).service_data.dtcs, 20, 0.3, "a confirmed DTC")
            dtc = c.get_dtc_by_status_mask(CONFIRMED).service_data.dtcs[0].id
        out = diag(ddct, "dtc", "--iface", "vcan0")
        assert f"DTC {dtc:#08x}" in out and "confirmedDTC" in out, out
        assert "EngineSpeed =" in out and "extended data: 01" in out, out
        out = diag(ddct, "clear", "--iface", "vcan0")
        assert "cleared 0xffffff" in out
        assert "no DTC matches" in diag(ddct, "dtc", "--iface", "vcan0", "--mask", "0x08")
        diag(ddct, "write-cal", "--iface", "vcan0", "control.clutch_kp_per_s", "12.5")
        with uds_client() as c:
            v = c.read_data_by_identifier(CAL_DID["control.clutch_kp_per_s"]).service_data.values
            assert v[CAL_DID["control.clutch_kp_per_s"]] == 12.5
        time.sleep(0.5)
        out = diag(ddct, "kiss-point", "--iface", "vcan0", "--clutch", "2")
        m = re.search(r"clutch 2: learned kiss point ([0-9.]+) mm", out)
        assert m and abs(float(m.group(1)) - 4.0) < 0.05, out
        assert "reset" in diag(ddct, "reset", "--iface", "vcan0")
        time.sleep(0.5)
        out = diag(ddct, "read-did", "--iface", "vcan0", "control.clutch_kp_per_s", "LearnedKiss2")
        assert "control.clutch_kp_per_s = 8 1/s" in out, out  # the file's value again
        kept = re.search(r"LearnedKiss2 = ([0-9.]+) mm", out)  # kept across the reset
        assert kept and abs(float(kept.group(1)) - float(m.group(1))) < 0.001, out


def test_ddct_diag_names_a_negative_response(ddct, tmp_path):
    with bench(ddct, tmp_path):
        r = subprocess.run([str(ddct), "diag", "read-did", "--iface", "vcan0", "0xABCD"],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode != 0
        assert "NRC 0x31 (requestOutOfRange)" in r.stderr, r.stderr
