"""ESC_STATUS (291): definition-derived CRC, and round trips through pymavlink readers."""

from pymavlink import mavutil
from pymavlink.dialects.v20 import common
from pymavlink.generator import mavparse

from monitor.mavlink import esc as mavlink_esc

ESC_XML = """<?xml version="1.0"?>
<mavlink><version>3</version><messages>
<message id="291" name="ESC_STATUS"><description>x</description>
  <field type="uint8_t" name="index">i</field>
  <field type="uint64_t" name="time_usec" units="us">t</field>
  <field type="int32_t[4]" name="rpm" units="rpm">r</field>
  <field type="float[4]" name="voltage" units="V">v</field>
  <field type="float[4]" name="current" units="A">c</field>
</message></messages></mavlink>"""


def test_crc_extra_and_length_match_the_published_definition(tmp_path):
    p = tmp_path / "esc.xml"
    p.write_text(ESC_XML)
    msg = mavparse.MAVXML(str(p), "2.0").message[0]
    assert msg.crc_extra == mavlink_esc.CRC_EXTRA_ESC_STATUS
    assert msg.wire_length == mavlink_esc.MAVLink_esc_status_message.unpacker.size == 57
    assert [f.name for f in msg.ordered_fields] == mavlink_esc.MAVLink_esc_status_message.ordered_fieldnames


def _write_tlog(path, n=5):
    mav = common.MAVLink(None, srcSystem=1, srcComponent=1)
    with open(path, "wb") as f:
        for k in range(n):
            buf = mavlink_esc.encode_esc_status(mav, 1_000_000 + k * 50_000, [5000 + k, 5100, 5200, 5300], [15.0] * 4, [3.0] * 4)
            f.write((1_700_000_000_000_000 + k).to_bytes(8, "big") + buf)
            f.write(
                (1_700_000_000_000_000 + k).to_bytes(8, "big") + common.MAVLink_attitude_message(k, 0, 0, 0, 0, 0, 0).pack(mav)
            )


def test_stock_reader_does_not_know_291_but_registered_reader_decodes(tmp_path):
    path = tmp_path / "esc.tlog"
    _write_tlog(path)
    mavlink_esc.register()
    conn = mavutil.mavlink_connection(str(path))
    got = []
    while True:
        m = conn.recv_match(type=["ESC_STATUS", "ATTITUDE"])
        if m is None:
            break
        if m.get_type() == "ESC_STATUS":
            got.append(mavlink_esc.decode_esc_status(m))
    assert len(got) == 5
    assert got[2] == (0, 1_100_000, [5002, 5100, 5200, 5300])


def test_decode_from_unknown_message_bytes():
    mav = common.MAVLink(None, srcSystem=1, srcComponent=1)
    buf = mavlink_esc.encode_esc_status(mav, 123456789, [1, -2, 3, 4])
    parser = common.MAVLink(None)
    saved = common.mavlink_map.pop(291, None)
    try:
        msg = parser.decode(bytearray(buf))
        assert msg.get_type() == "UNKNOWN_291"
        assert mavlink_esc.decode_esc_status(msg) == (0, 123456789, [1, -2, 3, 4])
    finally:
        if saved is not None:
            common.mavlink_map[291] = saved
