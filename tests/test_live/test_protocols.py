"""The scanners' wire protocols, byte for byte: SICK CoLa-A LMDscandata and Hokuyo SCIP 2.0."""

from __future__ import annotations

import contextlib
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from mast.core.scan import Scan
from mast.errors import InputError
from mast.live.protocols import PROTOCOLS, hokuyo, protocol, sick
from mast.live.tcp import TcpSource

# --- SICK CoLa-A -------------------------------------------------------------------------

#: The header of an LMS1xx scan as printed in SICK's telegram listing: 541 beams of 0.5 deg
#: from -45 deg (telegram angles), 50 Hz, distances in mm (scale 1.0).
LMS1XX_HEAD = (
    b"sRA LMDscandata 1 1 89A27F 0 0 343 347 27477BA9 2747863C 0 0 7 0 0 1388 168 0 1 "
    b"DIST1 3F800000 00000000 FFF92230 1388 21D "
)
#: A TiM's streamed scan (SICK's open TiM driver's example): 271 beams of 1 deg, 15 Hz.
TIM_HEAD = (
    b"sSN LMDscandata 1 1 B96518 0 0 99 9A 13C8E59 13C9CBE 0 0 8 0 0 5DC 36 0 1 "
    b"DIST1 3F800000 00000000 FFF92230 2710 10F "
)


def _telegram(head: bytes, values: list[int], tail: bytes = b" 0 0 0 0 0 0") -> bytes:
    return head + b" ".join(f"{v:X}".encode() for v in values) + tail


def test_an_lms1xx_telegram_gives_beams_from_minus_135_to_135_degrees() -> None:
    values = [1000 + k for k in range(541)]
    values[10] = 0  # no return
    t = sick.parse_scandata(_telegram(LMS1XX_HEAD, values))
    assert (t.device_status, t.telegram_counter, t.scan_counter) == (0, 0x343, 0x347)
    assert t.time_since_startup_us == 0x27477BA9
    assert t.scan_frequency_hz == 50.0
    assert (t.start_angle_deg, t.step_deg) == (-45.0, 0.5)
    scan = t.to_scan(range_min_m=0.05, range_max_m=20.0, stamp_ns=7)
    assert len(scan) == 541
    assert math.degrees(scan.angles_rad[0]) == pytest.approx(-135.0)
    assert math.degrees(scan.angles_rad[-1]) == pytest.approx(135.0)
    assert math.degrees(scan.angles_rad[270]) == pytest.approx(0.0, abs=1e-9)  # forward
    assert scan.ranges_m[270] == pytest.approx(1.270)
    assert not scan.valid[10]
    assert scan.stamp_ns == 7


def test_a_tim_telegram_with_a_remission_channel() -> None:
    values = list(range(500, 771))
    rssi = b" 1 RSSI1 3F800000 00000000 FFF92230 2710 10F " + b" ".join(b"C8" for _ in values)
    t = sick.parse_scandata(_telegram(TIM_HEAD, values, rssi + b" 0 0 0 0 0"))
    assert (t.start_angle_deg, t.step_deg, t.scan_frequency_hz) == (-45.0, 1.0, 15.0)
    assert t.rssi is not None
    assert t.rssi.size == 271
    assert t.rssi[0] == 200
    assert_allclose(t.distances_m, np.arange(500, 771) / 1000.0)


def test_a_scale_factor_of_two_doubles_the_distances() -> None:
    head = LMS1XX_HEAD.replace(b"3F800000", b"40000000")
    t = sick.parse_scandata(_telegram(head, [1500] * 541))
    assert_allclose(t.distances_m, 3.0)


def test_encoded_scans_read_back_to_the_millimetre() -> None:
    rng = np.random.default_rng(0)
    ranges = rng.uniform(0.5, 25.0, 1081)
    ranges[[3, 500]] = np.nan
    scan = Scan.from_laserscan(
        angle_min=math.radians(-135), angle_increment=math.radians(0.25), ranges=ranges
    )
    framed = sick.encode_scandata(
        scan, scan_counter=12, time_since_startup_us=99, scan_frequency_hz=25.0
    )
    buf = bytearray(b"\x00junk" + framed + framed[:40])
    (body,) = sick.split_telegrams(buf)
    assert bytes(buf) == framed[:40]  # the incomplete one waits for more bytes
    back = sick.parse_scandata(body).to_scan(range_min_m=0.0, range_max_m=30.0, stamp_ns=0)
    assert_allclose(back.angles_rad, scan.angles_rad, atol=math.radians(1e-4) * 1081)
    assert_allclose(back.ranges_m[scan.valid], scan.ranges_m[scan.valid], atol=0.0005)
    assert not back.valid[3]
    assert not back.valid[500]


@pytest.mark.parametrize(
    ("body", "says"),
    [
        (LMS1XX_HEAD[:60], "ends before"),
        (_telegram(LMS1XX_HEAD, [1] * 100), "holds fewer"),
        (b"sRA LMDscandata2 1", "not an LMDscandata"),
        (_telegram(LMS1XX_HEAD.replace(b"DIST1", b"RSSI1"), [1] * 541), "no DIST1"),
        (_telegram(LMS1XX_HEAD.replace(b"21D", b"0"), []), "declares 0 values"),
        (LMS1XX_HEAD + b" ".join([b"XYZ"] + [b"1"] * 540) + b" 0 0 0 0 0 0", "not a hex"),
    ],
)
def test_malformed_telegrams_are_named(body: bytes, says: str) -> None:
    with pytest.raises(InputError, match=says):
        sick.parse_scandata(body)


def test_a_telegram_that_never_ends_is_dropped_and_counted() -> None:
    buf = bytearray(sick.STX + b"A" * (sick.MAX_TELEGRAM_BYTES + 1))
    assert sick.split_telegrams(buf) == [b""]
    assert not buf


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_any_bytes_are_a_telegram_or_an_input_error(data: bytes) -> None:
    for body in (data, LMS1XX_HEAD + data, TIM_HEAD[:50] + data):
        with contextlib.suppress(InputError):
            sick.parse_scandata(body)


# --- Hokuyo SCIP 2.0 ---------------------------------------------------------------------

UST = hokuyo.DeviceParameters("UST-20LX", 20, 60000, 1440, 0, 1080, 540, 2400)


def test_the_specification_examples_of_encoding_and_sums() -> None:
    # SCIP 2.0: 1234 in two characters is "CB", 5432 in three is "1Dh"; "00P" and "99b"
    assert hokuyo.encode(1234, 2) == b"CB"
    assert hokuyo.encode(5432, 3) == b"1Dh"
    assert hokuyo.decode(b"1DhCB0", 3).tolist() == [5432, 19 * 4096 + 18 * 64]
    assert chr(hokuyo.checksum(b"00")) == "P"
    assert chr(hokuyo.checksum(b"99")) == "b"


def test_decode_reads_each_group_most_significant_first() -> None:
    values = [0, 1, 63, 64, 4095, 5432, 262143]
    data = b"".join(hokuyo.encode(v, 3) for v in values)
    assert hokuyo.decode(data, 3).tolist() == values


def test_parameters_read_back() -> None:
    reply = hokuyo.encode_parameters(UST)
    (body,) = hokuyo.split_replies(bytearray(reply))
    assert hokuyo.parse_parameters(body) == UST
    assert UST.angle(540) == 0.0
    assert math.degrees(UST.angle(0)) == pytest.approx(-135.0)


def test_a_distance_reply_reads_back_with_its_steps_and_stamp() -> None:
    d = np.arange(1081, dtype=np.int64) * 10 + 100
    d[7] = 1  # an error code (below DMIN): no return
    reply = hokuyo.encode_distance_reply(d, first_step=0, timestamp_ms=123456, remaining=0)
    (body,) = hokuyo.split_replies(bytearray(reply + b"MD00"))
    r = hokuyo.parse_distance_reply(body)
    assert (r.first_step, r.last_step, r.timestamp_ms) == (0, 1080, 123456)
    assert r.distances_mm.tolist() == d.tolist()
    scan = r.to_scan(UST, stamp_ns=5)
    assert math.degrees(scan.angles_rad[0]) == pytest.approx(-135.0)
    assert math.degrees(scan.angles_rad[540]) == pytest.approx(0.0, abs=1e-9)
    assert scan.ranges_m[540] == pytest.approx(5.5)
    assert not scan.valid[7]
    lines = body.split(b"\n")
    assert all(len(line) == 65 for line in lines[3:-1])  # 64 data characters and a sum


def test_a_flipped_bit_fails_the_sum_check() -> None:
    reply = bytearray(
        hokuyo.encode_distance_reply(np.full(100, 1500), first_step=490, timestamp_ms=1)
    )
    at = reply.index(b"\n", reply.index(b"\n", reply.index(b"\n") + 1) + 1) + 5
    reply[at] ^= 0x01
    (body,) = hokuyo.split_replies(reply)
    with pytest.raises(InputError, match="sum check"):
        hokuyo.parse_distance_reply(body)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_any_bytes_are_a_reply_or_an_input_error(data: bytes) -> None:
    for body in (data, b"MD0000108001000\n99b\n" + data, b"PP\n00P\n" + data):
        for parse in (hokuyo.parse_distance_reply, hokuyo.parse_parameters):
            with contextlib.suppress(InputError):
                parse(body)


def test_a_signed_scale_factor_is_a_malformed_telegram_not_a_crash() -> None:
    head = LMS1XX_HEAD.replace(b"DIST1 3F800000", b"DIST1 -1000000")
    with pytest.raises(InputError, match=r"scale factor .* is not 8 hex digits"):
        sick.parse_scandata(_telegram(head, [1000] * 541))


def test_impossible_step_geometry_in_pp_is_refused() -> None:
    p = hokuyo.DeviceParameters("UST", 20, 30000, 0, 0, 1080, 540, 2400)
    with pytest.raises(InputError, match="step geometry is impossible"):
        hokuyo.parse_parameters(hokuyo.encode_parameters(p))


# --- the registry ------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(PROTOCOLS))
def test_every_protocol_reads_back_what_its_device_sends(name: str) -> None:
    """Each protocol's three parts agree: the device's telegram, read by the codec as the
    client reads it, is the scan again (ranges to the millimetre, no return kept)."""
    p = protocol(name)
    assert p.name == name
    assert p.url == f"{name}://HOST[:PORT]"
    assert issubclass(p.source, TcpSource)
    angles = np.radians(np.arange(-135.0, 135.0 + 1e-9, 0.25))
    ranges = np.random.default_rng(1).uniform(0.2, 25.0, angles.size)
    ranges[::7] = np.inf
    scan = Scan(angles, ranges, stamp_ns=5)
    device = p.emulation(scan)
    sent = device.encode(scan, ticks=1234, counter=3, hz=25.0)
    back = device.read_back(sent, stamp_ns=987)
    assert back.stamp_ns == 987
    assert_allclose(back.angles_rad, angles, atol=1e-6)
    assert np.array_equal(back.valid, scan.valid)
    assert_allclose(back.ranges_m[back.valid], ranges[scan.valid], atol=0.0005 + 1e-12)
    with pytest.raises(InputError):
        device.read_back(device.corrupt(sent), stamp_ns=0)


def test_an_unknown_protocol_names_the_known_ones() -> None:
    with pytest.raises(InputError, match=r"unknown scanner kind 'velodyne'; known: sick, hokuyo"):
        protocol("velodyne")
