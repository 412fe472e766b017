"""Synthetic VLP-16 packet captures for the tests: classic pcap files of Ethernet/IPv4/UDP
frames carrying VLP-16 data packets (VLP-16 user manual, "Data Packet Format").

A data packet is 1206 bytes: 12 firing blocks of 100 bytes (flag ``FF EE``, azimuth in
hundredths of a degree, 32 returns of distance in 2 mm units and reflectivity), then the
device time (microseconds past the hour), the return-mode byte and the product id.

Examples
--------
>>> data = vlp16_capture(n_packets=3)
>>> len(data) == 24 + 3 * (16 + ETHERNET_FRAME_BYTES)
True
"""

from __future__ import annotations

import struct

#: VLP-16 data packet (the UDP payload), bytes
DATA_PACKET_BYTES = 1206
#: Ethernet (14) + IPv4 (20) + UDP (8) headers before the payload, bytes
ETHERNET_FRAME_BYTES = 14 + 20 + 8 + DATA_PACKET_BYTES
STRONGEST, LAST, DUAL = 0x37, 0x38, 0x39
VLP16_PRODUCT_ID = 0x22
#: Azimuth advance of one firing block at 600 rpm, degrees
BLOCK_STEP_DEG = 0.4
#: Time between data packets at 600 rpm, seconds
PACKET_PERIOD_S = 1.327e-3
LINKTYPE_ETHERNET = 1
#: UNIX time of the first packet, seconds
START_S = 1599213600.0


def vlp16_packet(azimuth_deg: float, device_time_us: int, return_mode: int = STRONGEST,
                 product_id: int = VLP16_PRODUCT_ID, distance_m: float = 3.0,
                 dual_strongest_m: float = 2.0) -> bytes:
    """One 1206-byte data packet: 12 blocks from ``azimuth_deg`` on, every return at
    ``distance_m`` (metres) with reflectivity 100. In dual-return mode the blocks go in pairs
    of one azimuth: the last return (``distance_m``), then the strongest (``dual_strongest_m``,
    reflectivity 200)."""
    def block(azimuth: float, distance: float, reflectivity: int) -> bytes:
        return (b"\xff\xee" + struct.pack("<H", round(100 * azimuth) % 36000)
                + struct.pack("<HB", round(distance / 0.002), reflectivity) * 32)

    if return_mode == DUAL:
        pairs = [azimuth_deg + k * BLOCK_STEP_DEG for k in range(6)]
        blocks = [block(a, distance_m, 100) + block(a, dual_strongest_m, 200) for a in pairs]
    else:
        blocks = [block(azimuth_deg + k * BLOCK_STEP_DEG, distance_m, 100) for k in range(12)]
    return b"".join(blocks) + struct.pack("<IBB", device_time_us % 3_600_000_000, return_mode,
                                          product_id)


def ethernet_frame(payload: bytes, port: int = 2368) -> bytes:
    """``payload`` as a UDP datagram from 192.168.1.201 to 255.255.255.255, port ``port``."""
    udp = struct.pack(">HHHH", port, port, 8 + len(payload), 0)
    ip = struct.pack(">BBHHHBBH4s4s", 0x45, 0, 20 + len(udp) + len(payload), 0, 0x4000, 64, 17,
                     0, bytes([192, 168, 1, 201]), b"\xff\xff\xff\xff")
    return b"\xff" * 6 + bytes.fromhex("607688381ec1") + b"\x08\x00" + ip + udp + payload


def pcap_file(records: list[tuple[float, bytes]], link_type: int = LINKTYPE_ETHERNET,
              snaplen: int = 262144, magic: int = 0xA1B2C3D4) -> bytes:
    """A little-endian classic pcap of ``(time_s, frame)`` records; a frame longer than
    ``snaplen`` is saved cut to it (its original length kept in the record header)."""
    out = [struct.pack("<IHHiIII", magic, 2, 4, 0, 0, snaplen, link_type)]
    for time_s, frame in records:
        seconds = int(time_s)
        saved = frame[:snaplen]
        out.append(struct.pack("<IIII", seconds, round((time_s - seconds) * 1e6), len(saved),
                               len(frame)) + saved)
    return b"".join(out)


def vlp16_frames(n_packets: int, return_mode: int = STRONGEST,
                 product_id: int = VLP16_PRODUCT_ID) -> list[tuple[float, bytes]]:
    """``n_packets`` consecutive data packets of a spinning VLP-16 as ``(time_s, frame)``."""
    step_deg = (6 if return_mode == DUAL else 12) * BLOCK_STEP_DEG
    return [(START_S + k * PACKET_PERIOD_S,
             ethernet_frame(vlp16_packet(k * step_deg, round(k * PACKET_PERIOD_S * 1e6),
                                         return_mode, product_id)))
            for k in range(n_packets)]


def vlp16_capture(n_packets: int = 8, **packet_options) -> bytes:
    """A valid capture of ``n_packets`` data packets (``packet_options``: ``return_mode``,
    ``product_id``)."""
    return pcap_file(vlp16_frames(n_packets, **packet_options))


def raw_ip_frame(frame: bytes) -> bytes:
    """An Ethernet frame as link type 101 (raw IP) saves it: without the Ethernet header."""
    return frame[14:]


def linux_sll_frame(frame: bytes) -> bytes:
    """An Ethernet frame as link type 113 (Linux cooked, ``tcpdump -i any``) saves it."""
    return struct.pack(">HHH8sH", 0, 1, 6, frame[6:12] + b"\0\0", 0x0800) + frame[14:]


def pcapng_header() -> bytes:
    """A pcapng file's first block (section header), what Wireshark saves by default."""
    return struct.pack("<IIIHHqI", 0x0A0D0D0A, 28, 0x1A2B3C4D, 1, 0, -1, 28)
