"""Which DDS implementation a GUID or an RTPS message comes from: its two-byte vendor id.

Every RTPS message header carries the sender's vendor id, and Fast DDS and Cyclone DDS also begin
each GUID prefix with it. The ids are assigned by the OMG (the DDS Foundation's list "DDSI-RTPS
Vendor and Product IDs"); this table holds the ones a course participant is likely to meet.
"""

from __future__ import annotations

VENDORS = {
    (0x01, 0x01): "RTI Connext DDS",
    (0x01, 0x02): "ADLINK OpenSplice DDS",
    (0x01, 0x0F): "eProsima Fast DDS",
    (0x01, 0x10): "Eclipse Cyclone DDS",
    (0x01, 0x12): "RTI Connext Micro",
}


def vendor_name(first: int, second: int) -> str:
    """The implementation behind vendor id ``first.second`` ('vendor 01.99' for one not listed)."""
    return VENDORS.get((first, second), f"vendor {first:02x}.{second:02x}")


def gid_vendor(gid) -> str:
    """The vendor of a GUID (bytes, or the list of ints rclpy gives as ``endpoint_gid``)."""
    raw = bytes(gid)
    return vendor_name(raw[0], raw[1])


def gid_prefix(gid) -> str:
    """The participant part (first 12 bytes) of a GUID, as dotted hex (``01.10.0d.22...``)."""
    return ".".join(f"{b:02x}" for b in bytes(gid)[:12])
