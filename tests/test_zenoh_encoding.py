"""The wire encoding of the Zenoh bridge (no Zenoh needed): exact round trips, every
refusal, and ROS 2's CDR of sensor_msgs/JointState against a layout written by hand."""

from __future__ import annotations

import struct

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from sotpy.bridge.encoding import (
    HEADER,
    SampleError,
    checked,
    decode,
    decodeJointState,
    encode,
    encodeJointState,
    expectedShape,
    pack,
)
from sotpy.errors import BridgeError

finite_or_inf = st.floats(allow_nan=False, width=64)


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, st.integers(0, 50), elements=finite_or_inf), st.integers(0, 2**63))
def test_vector_round_trip_is_exact(v, seq):
    seq2, tick, back = decode(encode("vector", v, seq, -3), "vector")
    assert (seq2, tick) == (seq, -3)
    assert back.dtype == np.float64 and back.shape == v.shape
    assert back.tobytes() == v.tobytes()  # every bit, infinities and -0.0 included


@settings(max_examples=40, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(0, 7), st.integers(0, 7)), elements=finite_or_inf))
def test_matrix_round_trip_is_exact_and_row_major(m):
    data = encode("matrix", m, 1, 2)
    rows, cols = struct.unpack_from("<II", data, HEADER.size)
    assert (rows, cols) == m.shape
    # the entries follow row by row, whatever the array's memory order
    assert data[HEADER.size + 8 :] == np.ascontiguousarray(m).tobytes()
    assert decode(encode("matrix", np.asfortranarray(m), 1, 2), "matrix")[2].tobytes() == (
        np.ascontiguousarray(m).tobytes()
    )


def test_a_checked_value_is_a_copy_for_the_send_thread():
    """The publisher's trigger checks and copies on the tick's thread, its send thread
    packs later: the signal's array written in place meanwhile must not reach the
    sample."""
    v = np.arange(38.0)
    M = pin.SE3(pin.utils.rpyToMatrix(0.1, -0.2, 0.3), np.array([1.0, 2.0, 3.0]))
    jobs = [("vector", v, (38,)), ("matrix", v.reshape(2, 19), (2, 19)), ("SE3", M, None)]
    out = [(name, checked(name, value, shape)) for name, value, shape in jobs]
    v[:] = -1.0
    M.translation = np.zeros(3)
    _, _, got = decode(pack(*out[0][1], 1, 2), "vector", (38,))
    assert np.array_equal(got, np.arange(38.0))
    _, _, got = decode(pack(*out[1][1], 1, 2), "matrix", (2, 19))
    assert np.array_equal(got, np.arange(38.0).reshape(2, 19))
    _, _, got = decode(pack(*out[2][1], 1, 2), "SE3")
    assert np.array_equal(got.translation, [1.0, 2.0, 3.0])


def test_scalars_se3_and_string_round_trip():
    assert decode(encode("double", -1.5e300, 0, 0), "double")[2] == -1.5e300
    assert decode(encode("double", float("inf"), 0, 0), "double")[2] == float("inf")
    assert decode(encode("int", -(2**63), 0, 0), "int")[2] == -(2**63)
    assert decode(encode("bool", True, 0, 0), "bool")[2] is True
    assert decode(encode("bool", False, 0, 0), "bool")[2] is False
    assert decode(encode("string", "pied gauche é", 0, 0), "string")[2] == "pied gauche é"
    M = pin.SE3.Random()
    back = decode(encode("SE3", M, 4, 5), "SE3")[2]
    assert isinstance(back, pin.SE3)
    assert np.array_equal(back.homogeneous, M.homogeneous)


def test_header_layout_is_the_documented_one():
    data = encode("vector", np.array([1.0, 2.0]), seq=7, tick=-2)
    assert data[:4] == b"SOTZ" and data[4] == 1 and data[5] == 4
    assert struct.unpack_from("<HQq", data, 6) == (0, 7, -2)
    assert struct.unpack_from("<II2d", data, 24) == (2, 0, 1.0, 2.0)
    assert len(data) == 24 + 8 + 16


def _refused(data, typeName="vector", shape=None, limit=1 << 20):
    with pytest.raises(SampleError) as info:
        decode(data, typeName, shape, limit)
    return info.value.reason


def test_every_malformed_sample_is_refused_with_its_reason():
    good = encode("vector", np.arange(3.0), 0, 0)
    assert _refused(good[:10]) == "header"  # shorter than the header
    assert _refused(b"XXXX" + good[4:]) == "header"  # not ours
    assert _refused(good[:4] + b"\x02" + good[5:]) == "version"
    assert _refused(good[:6] + b"\x01\x00" + good[8:]) == "header"  # flags set
    assert _refused(encode("double", 1.0, 0, 0)) == "type"  # a double on a vector key
    assert _refused(good[:5] + b"\x63" + good[6:]) == "type"  # unknown type code
    assert _refused(good[:-1]) == "size"  # truncated
    assert _refused(good + b"\x00") == "size"  # one byte too many
    assert _refused(good, shape=(4,)) == "size"  # not the declared size
    assert _refused(good, limit=len(good) - 1) == "oversized"
    nan = bytearray(good)
    nan[-8:] = struct.pack("<d", float("nan"))
    assert _refused(bytes(nan)) == "value"
    bad_bool = bytearray(encode("bool", True, 0, 0))
    bad_bool[-1] = 2
    assert _refused(bytes(bad_bool), "bool") == "value"
    assert _refused(encode("int", 3, 0, 0)[:-1], "int") == "size"
    s = bytearray(encode("string", "ab", 0, 0))
    s[-2:] = b"\xff\xfe"
    assert _refused(bytes(s), "string") == "value"
    # a vector announcing more entries than it carries
    lying = bytearray(good)
    lying[24:28] = struct.pack("<I", 1000)
    assert _refused(bytes(lying)) == "size"


def test_se3_rotation_must_be_a_rotation():
    M = pin.SE3.Random()
    data = bytearray(encode("SE3", M, 0, 0))
    R = M.rotation.copy()
    R[0, 0] += 1e-6  # no longer orthonormal
    data[24 + 24 :] = np.ascontiguousarray(R).tobytes()
    assert _refused(bytes(data), "SE3") == "value"
    data[24 + 24 :] = np.ascontiguousarray(-M.rotation).tobytes()  # det -1: a reflection
    assert _refused(bytes(data), "SE3") == "value"
    assert _refused(bytes(data[:-8]), "SE3") == "size"


def test_encode_refuses_what_decode_would():
    with pytest.raises(SampleError):
        encode("vector", np.array([1.0, np.nan]), 0, 0)
    with pytest.raises(SampleError):
        encode("vector", np.zeros(3), 0, 0, shape=(4,))
    with pytest.raises(SampleError):
        encode("vector", np.zeros((2, 2)), 0, 0)
    with pytest.raises(SampleError):
        encode("vector", np.zeros(1000), 0, 0, limit=100)
    with pytest.raises(BridgeError, match="no wire encoding"):
        encode("any", 1, 0, 0)


def test_declared_shapes():
    assert expectedShape("vector", 38) == (38,)
    assert expectedShape("matrix", (6, 38)) == (6, 38)
    assert expectedShape("vector", None) is None
    for bad in (("vector", -1), ("vector", 2.5), ("matrix", 3), ("double", 1)):
        with pytest.raises(BridgeError):
            expectedShape(*bad)


def test_joint_state_cdr_matches_the_layout_written_by_hand():
    data = encodeJointState(["a", "bc"], [1.0, 2.0], [], [0.5, -0.5], stamp=1.25, frameId="")
    # OMG CDR little-endian, alignment counted after the 4-byte encapsulation header
    expected = (
        b"\x00\x01\x00\x00"  # encapsulation: CDR_LE
        + struct.pack("<iI", 1, 250_000_000)  # stamp (offsets 0, 4)
        + struct.pack("<I", 1)
        + b"\x00"  # frame_id "" (length 1: the NUL), offset 8..13
        + b"\x00" * 3
        + struct.pack("<I", 2)  # two names, offset 16
        + struct.pack("<I", 2)
        + b"a\x00"  # offset 20..26
        + b"\x00" * 2
        + struct.pack("<I", 3)
        + b"bc\x00"  # offset 28..35
        + b"\x00"
        + struct.pack("<I", 2)  # position count at 36, doubles at 40 (8-aligned)
        + struct.pack("<2d", 1.0, 2.0)
        + struct.pack("<I", 0)  # velocity: empty, offset 56
        + struct.pack("<I", 2)  # effort count at 60, doubles at 64
        + struct.pack("<2d", 0.5, -0.5)
    )
    assert data == expected
    msg = decodeJointState(data)
    assert msg["name"] == ["a", "bc"] and msg["frame_id"] == ""
    assert msg["stamp"] == pytest.approx(1.25, abs=1e-9)
    assert np.array_equal(msg["position"], [1.0, 2.0])
    assert msg["velocity"].size == 0
    assert np.array_equal(msg["effort"], [0.5, -0.5])


def test_joint_state_cdr_refusals():
    data = encodeJointState(["j1"], [0.1], [0.2], [0.3], stamp=2.0, frameId="base")
    assert decodeJointState(data)["frame_id"] == "base"
    for bad in (data[:-1], data + b"\x00", b"\x00\x00" + data[2:]):
        with pytest.raises(SampleError):
            decodeJointState(bad)
    with pytest.raises(BridgeError, match="position has 2 entries for 1"):
        encodeJointState(["j1"], [0.1, 0.2])
