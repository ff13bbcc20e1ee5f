"""UDS (ISO 14229-1) against the TCU daemon on vcan0, with udsoncan over can-isotp as the tester
(issue 16): identification and live DIDs, a fault injected through the plant's fault file read
back as a confirmed DTC with its snapshot, clear, the fault memory across restarts, the
kiss-point routine, SecurityAccess and the calibration write, and every negative response.

Expectations are the documented contract (docs/diagnostics.md) and the bus itself (TCU_Estimates,
ENG_Status, DCT_Sensors as recorded), never values computed by ddct's diagnostic code.
"""

from __future__ import annotations

import math
import time
import tomllib

import can
import pytest
import udsoncan
from udsoncan.exceptions import NegativeResponseException
from udsoncan.services import ECUReset, DiagnosticSessionControl, RoutineControl

import ddct_can
from diag_helpers import (CAL_DID, FUNC_ID, REQ_ID, CONFIRMED, DID, FAILED_SINCE_CLEAR, KISS_ROUTINE,
                          LEARNED_KISS_DID, NAME_DID, NOT_COMPLETED_THIS_CYCLE, PENDING, REPO,
                          SERIAL_DID, TEST_FAILED, TEST_FAILED_THIS_CYCLE, VERSION_DID, Recorder,
                          bench, f32, security_key, uds_client, wait_until)

DB = ddct_can.load_dbc()


def decode_last(frames, name):
    msg = DB.get_message_by_name(name)
    for f in reversed(frames):
        if f.arbitration_id == msg.frame_id:
            return f, msg.decode(f.data, decode_choices=False)
    return None, None


def raw(client, payload: bytes) -> bytes:
    """A raw request; the raw response (positive or negative)."""
    client.conn.empty_rxqueue()
    client.conn.send(payload)
    return client.conn.wait_frame(timeout=3, exception=True)


# ------------------------------------------------------------------------------------------------
# identification, live values


def test_identification_and_live_values_match_the_bus(ddct, tmp_path):
    rec = Recorder()
    try:
        with bench(ddct, tmp_path, tcu_args=["--serial", "BENCH-42"]), uds_client() as c:
            time.sleep(1.5)
            assert c.read_data_by_identifier(SERIAL_DID).service_data.values[SERIAL_DID].strip() == "BENCH-42"
            version = c.read_data_by_identifier(VERSION_DID).service_data.values[VERSION_DID]
            assert version.startswith("ddct ") and len(version) == 16
            assert c.read_data_by_identifier(NAME_DID).service_data.values[NAME_DID].strip() == "ddct TCU"
            # Several DIDs in one request: a multi-frame request and response.
            dids = [DID["Clutch1TempEst"], DID["Clutch2TempEst"], DID["Clutch1TorqueRef"],
                    DID["Clutch2TorqueRef"], DID["EngineSpeed"], DID["TcuState"], DID["GearActive"]]
            for _ in range(5):
                before = rec.snapshot()
                values = c.read_data_by_identifier(dids).service_data.values
                after = rec.snapshot()
                _, est0 = decode_last(before, "TCU_Estimates")
                _, est1 = decode_last(after, "TCU_Estimates")
                for sig, did in (("Clutch1TempEst", DID["Clutch1TempEst"]),
                                 ("Clutch2TempEst", DID["Clutch2TempEst"])):
                    lo, hi = sorted((est0[sig], est1[sig]))
                    # within one quantum (0.1 degC) of the bus values around the request
                    assert lo - 0.1 <= values[did] <= hi + 0.1, (sig, values[did], lo, hi)
                _, st = decode_last(after, "TCU_Status")
                assert values[DID["TcuState"]] == st["TcuState"]
                _, eng = decode_last(after, "ENG_Status")
                assert abs(values[DID["EngineSpeed"]] - eng["EngSpeed"]) < 60.0
                time.sleep(0.2)
    finally:
        rec.close()


# ------------------------------------------------------------------------------------------------
# fault memory


FAULTS = """
[[faults]]
message = "ENG_Status"
kind = "corrupt_crc"
from_s = 4.0
to_s = 4.6
"""


def dtcs_by_mask(c, mask=0xFF):
    r = c.get_dtc_by_status_mask(mask)
    return {d.id: d.status.get_byte_as_int() for d in r.service_data.dtcs}


def test_injected_fault_is_a_confirmed_dtc_with_its_snapshot_kept_across_restarts(ddct, tmp_path):
    faults = tmp_path / "faults.toml"
    faults.write_text(FAULTS)
    memory = tmp_path / "fault_memory.json"
    log = tmp_path / "tcu.log"
    with bench(ddct, tmp_path, tcu_args=["--fault-memory", memory, "--log", log],
               plant_args=["--faults", faults]) as (b, _driver):
        with uds_client() as c:
            found = wait_until(lambda: dtcs_by_mask(c, CONFIRMED), 20, 0.3, "a confirmed DTC")
            assert len(found) == 1, found
            (dtc, status), = found.items()
            assert status & CONFIRMED and status & FAILED_SINCE_CLEAR and status & TEST_FAILED_THIS_CYCLE
            wait_until(lambda: not dtcs_by_mask(c, TEST_FAILED), 10, 0.3, "the fault healed")
            number = c.get_number_of_dtc_by_status_mask(CONFIRMED).service_data.dtc_count
            assert number == 1
            snap = raw(c, bytes([0x19, 0x04, dtc >> 16, (dtc >> 8) & 0xFF, dtc & 0xFF, 0x01]))
            ext = raw(c, bytes([0x19, 0x06, dtc >> 16, (dtc >> 8) & 0xFF, dtc & 0xFF, 0x01]))
        time.sleep(1.5)  # the memory is saved within a second of a change
        b.tcu.stop(10)
        b.restart("tcu")
        with uds_client() as c:
            after = dtcs_by_mask(c)
            assert dtc in after and after[dtc] & CONFIRMED, after
            assert not after[dtc] & TEST_FAILED
            c.clear_dtc(0xFFFFFF)
            assert not dtcs_by_mask(c, CONFIRMED)
        b.tcu.stop(10)
        b.restart("tcu")
        with uds_client() as c:
            assert not dtcs_by_mask(c, CONFIRMED)
    check_snapshot(snap, dtc, log)
    assert ext[:6] == bytes([0x59, 0x06, dtc >> 16, (dtc >> 8) & 0xFF, dtc & 0xFF, status & 0xFF]) or ext[0] == 0x59
    assert ext[6] == 0x01 and ext[7] >= 1, ext.hex()  # occurrence counter


def check_snapshot(snap: bytes, dtc: int, log):
    """The snapshot's operating conditions equal the bus log's at the first failure: the engine
    speed of the last ENG_Status the TCU accepted before its first TCU_Status with the fault."""
    assert snap[0] == 0x59 and snap[1] == 0x04, snap.hex()
    assert int.from_bytes(snap[2:5], "big") == dtc
    record_number, count = snap[6], snap[7]
    assert record_number == 0x01 and count >= 1
    values, i = {}, 8
    while i + 6 <= len(snap):
        did = int.from_bytes(snap[i:i + 2], "big")
        values[did] = f32(snap[i + 2:i + 6])
        i += 6
    assert DID["EngineSpeed"] in values, values
    frames = ddct_can.read_candump(log)
    status_id = DB.get_message_by_name("TCU_Status").frame_id
    eng_id = DB.get_message_by_name("ENG_Status").frame_id
    eng_speed = None
    for _t, _iface, fid, _ext, data in frames:
        if fid == eng_id:
            try:
                eng_speed = DB.decode_message(eng_id, data)["EngSpeed"]
            except Exception:
                pass
        if fid == status_id:
            st = DB.decode_message(status_id, data, decode_choices=False)
            if st["FaultCode"] != 0:
                break
    assert eng_speed is not None
    # The corrupted frames are not accepted: the snapshot holds the last valid engine speed,
    # and the speed at idle moves by a few rpm per cycle at most.
    assert abs(values[DID["EngineSpeed"]] - eng_speed) <= 25.0, (values, eng_speed)


# ------------------------------------------------------------------------------------------------
# kiss-point routine


def plant_kiss_point(theta_c: float) -> float:
    """x_ISP(theta) of (9) from config/params.toml, written here independently of the plant."""
    p = tomllib.loads((REPO / "config" / "params.toml").read_text())["clutch"]
    d = theta_c - p["theta_a_c"]
    return p["x_isp2_mm_per_c2"] * d * d + p["x_isp1_mm_per_c"] * d + p["x_isp0_mm"]


@pytest.mark.parametrize("clutch", [1, 2])
def test_kiss_point_routine_learns_the_plants_kiss_point(ddct, tmp_path, clutch):
    rec = Recorder(only=("SIM_Truth",))
    try:
        with bench(ddct, tmp_path), uds_client() as c:
            time.sleep(1.0)
            c.change_session(DiagnosticSessionControl.Session.extendedDiagnosticSession)
            c.start_routine(KISS_ROUTINE, bytes([clutch]))
            end = time.monotonic() + 60
            while True:
                c.tester_present()
                r = c.get_routine_result(KISS_ROUTINE).service_data.routine_status_record
                if r[0] == 2:
                    learned = f32(r[1:5])
                    break
                assert r[0] == 1, f"routine status {r.hex()}"
                assert time.monotonic() < end, "routine did not finish within 60 s"
                time.sleep(0.5)
            did = LEARNED_KISS_DID[clutch]
            assert c.read_data_by_identifier(did).service_data.values[did] == pytest.approx(learned)
        _, truth = decode_last(rec.snapshot(), "SIM_Truth")
        truth_kiss = plant_kiss_point(truth[f"Clutch{clutch}TempTrue"])
        print(f"clutch {clutch}: learned {learned:.4f} mm, plant {truth_kiss:.4f} mm, "
              f"error {learned - truth_kiss:+.4f} mm")
        assert abs(learned - truth_kiss) <= 0.05
    finally:
        rec.close()


# ------------------------------------------------------------------------------------------------
# security, calibration, sessions, reset


def test_security_access_and_calibration_write(ddct, tmp_path):
    with bench(ddct, tmp_path), uds_client() as c:
        kp = CAL_DID["control.clutch_kp_per_s"]
        old = c.read_data_by_identifier(kp).service_data.values[kp]
        # default session: service not supported in this session
        with pytest.raises(NegativeResponseException) as e:
            c.write_data_by_identifier(kp, 5.0)
        assert e.value.response.code == 0x7F
        c.change_session(DiagnosticSessionControl.Session.extendedDiagnosticSession)
        with pytest.raises(NegativeResponseException) as e:
            c.write_data_by_identifier(kp, 5.0)
        assert e.value.response.code == 0x33  # locked
        c.unlock_security_access(1)
        c.write_data_by_identifier(kp, old * 2)
        assert c.read_data_by_identifier(kp).service_data.values[kp] == pytest.approx(old * 2)
        with pytest.raises(NegativeResponseException) as e:
            c.write_data_by_identifier(kp, 1e6)  # outside 0 ..= 200
        assert e.value.response.code == 0x31
        assert c.read_data_by_identifier(kp).service_data.values[kp] == pytest.approx(old * 2)
        # ECUReset: the core restarts from its file calibration (RAM calibration lost)
        c.ecu_reset(ECUReset.ResetType.hardReset)
        time.sleep(0.5)
        assert c.read_data_by_identifier(kp).service_data.values[kp] == pytest.approx(old)


def test_wrong_keys_count_then_delay(ddct, tmp_path):
    with bench(ddct, tmp_path), uds_client() as c:
        c.change_session(DiagnosticSessionControl.Session.extendedDiagnosticSession)
        for attempt in range(3):
            seed = c.request_seed(1).service_data.seed
            bad = bytes(b ^ 0xFF for b in security_key(seed))
            with pytest.raises(NegativeResponseException) as e:
                c.send_key(2, bad)
            assert e.value.response.code == (0x36 if attempt == 2 else 0x35)
        with pytest.raises(NegativeResponseException) as e:
            c.request_seed(1)
        assert e.value.response.code == 0x37
        for _ in range(6):  # 10.5 s, the extended session kept alive
            time.sleep(1.75)
            c.tester_present()
        seed = c.request_seed(1).service_data.seed
        c.send_key(2, security_key(seed))


def test_session_times_out_without_tester_present(ddct, tmp_path):
    with bench(ddct, tmp_path), uds_client() as c:
        c.change_session(DiagnosticSessionControl.Session.extendedDiagnosticSession)
        time.sleep(2.5)
        c.tester_present()
        time.sleep(2.5)
        c.tester_present()  # kept alive past 5 s
        with pytest.raises(NegativeResponseException) as e:
            c.start_routine(KISS_ROUTINE, bytes([7]))  # a bad clutch number, extended session
        assert e.value.response.code == 0x31
        time.sleep(6.0)  # S3 = 5 s: back to the default session
        with pytest.raises(NegativeResponseException) as e:
            c.start_routine(KISS_ROUTINE, bytes([1]))
        assert e.value.response.code == 0x7F


# ------------------------------------------------------------------------------------------------
# negative responses, byte for byte (ISO 14229-1 / docs/diagnostics.md)

NRC_CASES = [
    # (request, expected response, why)
    ("ba", "7fba11", "unknown service"),
    ("1002", "7f1012", "programming session not supported"),
    ("10", "7f1013", "session control without a sub-function"),
    ("100300", "7f1013", "session control too long"),
    ("22f1", "7f2213", "a half DID"),
    ("22abcd", "7f2231", "unknown DID"),
    ("2e0200" + "40a00000", "7f2e7f", "write in the default session"),
    ("2701", "7f277f", "security in the default session"),
    ("310102" + "0101", "7f317f", "routine in the default session"),
    ("1905", "7f1912", "unsupported DTC report type"),
    ("1902", "7f1913", "DTC list without a mask"),
    ("14ffff", "7f1413", "clear with a short group"),
    ("14123456", "7f1431", "clear of an unknown DTC"),
    ("3e05", "7f3e12", "tester present with an unknown sub-function"),
    ("1104", "7f1112", "unsupported reset type"),
]

EXTENDED_NRC_CASES = [
    ("2702" + "00000000", "7f2724", "a key without a seed"),
    ("2e0200" + "40a00000", "7f2e33", "write while locked"),
    ("310302" + "01", "7f3124", "results of a routine never started"),
    ("3101ffff", "7f3131", "unknown routine"),
    ("31010201" + "03", "7f3131", "a clutch that does not exist"),
    # ISO 14229-1 checks security before the length of a supported DID's value.
    ("2e0200" + "40a0", "7f2e33", "write with a short value while locked"),
]

UNLOCKED_NRC_CASES = [
    ("2e0200" + "40a0", "7f2e13", "write with a short value"),
    ("2e0200" + "49742400", "7f2e31", "write out of range (1e6 for 0 ..= 200)"),
    ("2e0100" + "40a00000", "7f2e31", "write to a measurement"),
]


def test_every_negative_response(ddct, tmp_path):
    with bench(ddct, tmp_path), uds_client() as c:
        for req, want, why in NRC_CASES:
            assert raw(c, bytes.fromhex(req)).hex() == want, why
        assert raw(c, bytes.fromhex("1003"))[:2] == bytes.fromhex("5003")
        for req, want, why in EXTENDED_NRC_CASES:
            assert raw(c, bytes.fromhex(req)).hex() == want, why
        c.unlock_security_access(1)
        for req, want, why in UNLOCKED_NRC_CASES:
            assert raw(c, bytes.fromhex(req)).hex() == want, why


def test_routine_conditions_not_correct_while_driving(ddct, tmp_path):
    with bench(ddct, tmp_path) as (_b, driver), uds_client() as c:
        c.change_session(DiagnosticSessionControl.Session.extendedDiagnosticSession)
        driver.drive(brake=True)
        time.sleep(0.5)
        with pytest.raises(NegativeResponseException) as e:
            c.start_routine(KISS_ROUTINE, bytes([1]))
        assert e.value.response.code == 0x22


def test_functional_requests(ddct, tmp_path):
    """A functional TesterPresent with the suppress bit gets nothing; a functional read (a
    single-frame response: a multi-frame one would need the tester's flow control on the
    physical id) is answered on the physical response id; a functional unknown service gets no
    NRC."""
    with bench(ddct, tmp_path), uds_client(txid=FUNC_ID) as c:
        r = raw(c, bytes([0x22, 0x01, 0x10]))
        assert r[:3] == bytes([0x62, 0x01, 0x10]) and len(r) == 7
        c.conn.send(bytes([0x3E, 0x80]))
        assert c.conn.wait_frame(timeout=0.5) is None
        c.conn.send(bytes([0xBA]))
        assert c.conn.wait_frame(timeout=0.5) is None


def test_malformed_and_out_of_order_frames_are_dropped_and_counted(ddct, tmp_path):
    with bench(ddct, tmp_path) as (b, _d):
        bus = can.Bus(interface="socketcan", channel="vcan0")
        bad = ["", "00", "08" + "11" * 7, "21" + "00" * 7, "30", "1001", "1fff" + "00" * 6, "f0" + "00" * 7, "2f"]
        for h in bad * 20:
            bus.send(can.Message(arbitration_id=REQ_ID, data=bytes.fromhex(h), is_extended_id=False))
            time.sleep(0.002)
        bus.shutdown()
        with uds_client() as c:
            assert c.read_data_by_identifier(NAME_DID).service_data.values[NAME_DID].strip() == "ddct TCU"
    iso = b.tcu_report["diag"]["isotp"]
    dropped = iso["malformed"] + iso["wrong_sequence"] + iso["unexpected_consecutive"] + iso["unexpected_flow_control"]
    assert dropped >= 20 * 5, iso
