"""Where ROS 2 data lives on Zenoh: key expressions, type names and hashes, the attachment
rmw_zenoh puts on every publication and the liveliness tokens of its graph. Pure functions
(strings and bytes); no Zenoh import.

Two ways a ROS 2 system puts topics on Zenoh:

- **rmw_zenoh** (``RMW_IMPLEMENTATION=rmw_zenoh_cpp``; the ROS nodes speak Zenoh themselves):
  ``<domain_id>/<topic>/<dds type name>/<type hash>``, e.g.
  ``0/robot1/chatter/std_msgs::msg::dds_::String_/RIHS01_df66…1a18``. The topic is the fully
  qualified name with its leading (and trailing) '/' stripped; the '/' inside it stay key
  separators (only liveliness tokens mangle '/' into '%'). The payload is the CDR message with
  its 4-byte encapsulation header. Followed: rmw_zenoh ``docs/design.md`` and
  ``liveliness_utils.cpp`` (``TopicInfo``, ``strip_slashes``) on rolling.
- **zenoh-bridge-ros2dds** (nodes on DDS, one bridge per robot): the key is the topic name
  without its leading '/', prefixed by the bridge's ``namespace`` setting when it has one
  (``ros2_name_to_key_expr`` in zenoh-plugin-ros2dds 1.10). Same CDR payload, no attachment.

What differs by distro (rmw_zenoh): Humble has no type hashes (REP-2016 came with Iron), so
rmw_zenoh's humble branch puts the literal ``TypeHashNotSupported`` where Jazzy and Kilted put
``RIHS01_<sha256 hex>`` (that literal is what interoperating implementations send and expect;
rmw_zenoh's humble sources were not at hand to read it in), so a Humble and a Jazzy node never
match on the same topic (`rmw_zenoh_subscription_key` matches both). The message definitions
gmmap uses are identical on the wire in the three distros (rosbags' Humble, Jazzy and Kilted
typestores agree, hashes included), and so is the attachment layout below.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from functools import cache
from typing import NamedTuple

from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from gmmap.errors import RosMessageError

DISTROS = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY, "kilted": Stores.ROS2_KILTED}
HUMBLE_TYPE_HASH = "TypeHashNotSupported"  # what rmw_zenoh on Humble puts in the hash chunk
GID_SIZE = 16  # RMW_GID_STORAGE_SIZE since Iron (24 in Humble's rmw headers: both parse)

_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"  # a ROS name token (expanded: no '~', no '{}')
_NAME = re.compile(rf"/?{_TOKEN}(/{_TOKEN})*")
_ROS_TYPE = re.compile(r"([A-Za-z][A-Za-z0-9_]*)/(msg|srv|action)/([A-Za-z][A-Za-z0-9_]*)")
_DDS_TYPE = re.compile(r"([A-Za-z][A-Za-z0-9_]*)::(msg|srv|action)::dds_::([A-Za-z][A-Za-z0-9_]*)_")
_HASH = re.compile(rf"RIHS01_[0-9a-f]{{64}}|{HUMBLE_TYPE_HASH}")


@cache
def typestore(distro: str) -> Typestore:
    """rosbags' message definitions for a distro ("humble", "jazzy", "kilted"), built once."""
    try:
        return get_typestore(DISTROS[distro.lower()])
    except (KeyError, AttributeError) as exc:
        raise RosMessageError(
            f"unknown ROS 2 distro {distro!r}; known: {', '.join(DISTROS)}"
        ) from exc


def dds_type_name(typename: str) -> str:
    """'sensor_msgs/msg/PointCloud2' → 'sensor_msgs::msg::dds_::PointCloud2_' (the CDR/DDS
    spelling rmw_zenoh puts in keys)."""
    m = _ROS_TYPE.fullmatch(typename) if isinstance(typename, str) else None
    if m is None:
        raise RosMessageError(f"not a ROS 2 type name like 'pkg/msg/Type': {typename!r}")
    return f"{m[1]}::{m[2]}::dds_::{m[3]}_"


def ros_type_name(dds_name: str) -> str:
    """The inverse of `dds_type_name`."""
    m = _DDS_TYPE.fullmatch(dds_name)
    if m is None:
        raise RosMessageError(f"not a DDS type name like 'pkg::msg::dds_::Type_': {dds_name!r}")
    return f"{m[1]}/{m[2]}/{m[3]}"


def type_hash(typename: str, distro: str = "jazzy") -> str:
    """The type-hash chunk of rmw_zenoh keys: 'RIHS01_<64 hex>' (REP-2016, computed by rosbags
    from the distro's definitions) on Jazzy and Kilted, 'TypeHashNotSupported' on Humble."""
    store = typestore(distro)
    dds_type_name(typename)  # validates the spelling
    if typename not in store.types:
        raise RosMessageError(f"{typename} is not a {distro} message type known to rosbags")
    if distro.lower() == "humble":
        return HUMBLE_TYPE_HASH
    return store.hash_rihs01(typename)


def _topic_chunks(topic: str, what: str = "topic") -> str:
    """A ROS 2 name as key chunks: leading/trailing '/' stripped, as rmw_zenoh's strip_slashes."""
    if not isinstance(topic, str) or not _NAME.fullmatch(topic.rstrip("/")):
        raise RosMessageError(
            f"{what} {topic!r} is not an expanded ROS 2 name ('/ns/name': letters, digits, '_', "
            "tokens not starting with a digit)"
        )
    return topic.strip("/")


def _domain(domain: int) -> int:
    if isinstance(domain, bool) or not isinstance(domain, int) or domain < 0:
        raise RosMessageError(f"ROS domain id must be an integer >= 0, got {domain!r}")
    return domain


def rmw_zenoh_key(topic: str, typename: str, domain: int = 0, distro: str = "jazzy") -> str:
    """The key rmw_zenoh publishes ``topic`` (fully qualified, e.g. '/robot1/scan') on."""
    chunks = _topic_chunks(topic)
    return f"{_domain(domain)}/{chunks}/{dds_type_name(typename)}/{type_hash(typename, distro)}"


def rmw_zenoh_subscription_key(topic: str, typename: str, domain: int = 0) -> str:
    """A key expression matching ``topic`` from rmw_zenoh publishers of every distro (any hash
    chunk: Humble's 'TypeHashNotSupported' as well as Jazzy's and Kilted's RIHS01)."""
    return f"{_domain(domain)}/{_topic_chunks(topic)}/{dds_type_name(typename)}/*"


def bridge_key(topic: str, namespace: str = "") -> str:
    """The key zenoh-bridge-ros2dds routes ``topic`` on; ``namespace`` is the bridge's
    ``namespace`` setting ('' or '/' for none), which prefixes every name it routes."""
    chunks = _topic_chunks(topic)
    if namespace in ("", "/"):
        return chunks
    return f"{_topic_chunks(namespace, 'namespace')}/{chunks}"


class RosKey(NamedTuple):
    """A parsed key: the topic ('/…'), and for rmw_zenoh keys its type and hash chunk."""

    topic: str
    typename: str | None
    type_hash: str | None


def parse_key(key: str, namespace: str = "") -> RosKey:
    """The topic (and type, hash) of an rmw_zenoh or zenoh-bridge-ros2dds key.

    rmw_zenoh keys are told apart by their shape (a digit-only first chunk, which no ROS name
    token can be, a DDS type name and a hash); anything else that is a ROS name is a bridge key,
    from which the bridge ``namespace`` is removed when the key starts with it.
    """
    if not isinstance(key, str) or not key or key != key.strip("/"):
        raise RosMessageError(f"not a key expression: {key!r}")
    parts = key.split("/")
    if len(parts) >= 4 and parts[0].isascii() and parts[0].isdigit():
        if not (_DDS_TYPE.fullmatch(parts[-2]) and _HASH.fullmatch(parts[-1])):
            raise RosMessageError(f"not an rmw_zenoh topic key (domain/topic/type/hash): {key!r}")
        topic = "/" + _topic_chunks("/".join(parts[1:-2]))
        return RosKey(topic, ros_type_name(parts[-2]), parts[-1])
    chunks = _topic_chunks(key, "key")
    if namespace not in ("", "/"):
        prefix = _topic_chunks(namespace, "namespace") + "/"
        chunks = chunks.removeprefix(prefix)
    return RosKey("/" + chunks, None, None)


# ---------------------------------------------------------------------------------------------
# rmw_zenoh's graph: liveliness tokens (liveliness_utils.cpp, jazzy = kilted; design.md's
# examples are the tests' golden strings). A node and each of its publishers and subscriptions
# hold one token; ROS 2 tools (`ros2 topic list`, `ros2 topic echo`) learn the graph from them:
#
#   @ros2_lv/<domain>/<zid>/<nid>/<id>/<NN|MP|MS|SS|SC>/<enclave>/<namespace>/<node>
#            [/<topic>/<dds type>/<type hash>/<qos>]
#
# <zid> is the session id as Zenoh prints it (lowercase hex, no leading zeros): rmw_zenoh takes
# zenoh-cpp's Id::to_string, zenoh-c's z_id_to_string, the same Rust Display as zenoh-python's
# str(ZenohId). (rmw_zenoh before zenoh-cpp, 2024, printed each byte unpadded: not followed.)
# <nid> and <id> count from 0 in one context; a node's token has its own id in both.
#
# Names have every '/' mangled into '%' ('/' alone: '%'). <qos> lists reliability, durability,
# history and depth, deadline, lifespan and liveliness; a component equal to rmw_zenoh's default
# (reliable, volatile, keep last, depth 42, infinite durations, automatic) is left empty.

LIVELINESS_PREFIX = "@ros2_lv"
ENTITIES = {"NN": "node", "MP": "publisher", "MS": "subscription", "SS": "service", "SC": "client"}
DEFAULT_DEPTH = 42
_ZID = re.compile(r"[0-9a-f]{1,32}")
# The <qos> chunk as qos_to_keyexpr writes it (ASCII: '\d' takes other scripts' digits too).
_QOS = re.compile(r"\d*:\d*:\d*,\d*:\d*,\d*:\d*,\d*:\d*,\d*,\d*", re.ASCII)


class LivelinessToken(NamedTuple):
    """One rmw_zenoh graph entity; ``topic``, ``typename``, ``type_hash``, ``qos`` for topics."""

    domain: int
    zid: str
    node_id: int
    entity_id: int
    kind: str  # a key of ENTITIES
    namespace: str
    node: str
    topic: str | None = None
    typename: str | None = None
    type_hash: str | None = None
    qos: str | None = None


def _mangle(name: str) -> str:
    return name.replace("/", "%")


def _demangle(chunk: str) -> str:
    return chunk.replace("%", "/")


def qos_chunk(depth: int = DEFAULT_DEPTH) -> str:
    """The <qos> chunk of a reliable, volatile, keep-last endpoint of ``depth``."""
    return f"::,{'' if depth == DEFAULT_DEPTH else int(depth)}:,:,:,,"


def liveliness_token(
    zid: str, node_id: int, entity_id: int, kind: str, node: str, topic: str | None = None,
    typename: str | None = None, depth: int = DEFAULT_DEPTH, domain: int = 0,
    distro: str = "jazzy", namespace: str = "/",
) -> str:  # fmt: skip
    """The key of one entity's token: a node (``kind`` "NN") or, with ``topic`` and
    ``typename``, a publisher ("MP") or subscription ("MS"). The key is parsed back before it is
    returned, so a bad zid, id, name or depth is refused here, not by the ROS graph."""
    if kind not in ENTITIES:
        raise RosMessageError(f"liveliness token kind must be one of {sorted(ENTITIES)}: {kind!r}")
    head = f"{LIVELINESS_PREFIX}/{_domain(domain)}/{zid}/{node_id}/{entity_id}/{kind}"
    key = f"{head}/%/{_mangle(namespace)}/{node}"
    if kind != "NN":
        if topic is None or typename is None:
            raise RosMessageError(f"a {ENTITIES[kind]} token needs its topic and type")
        name, hashed = "/" + _topic_chunks(topic), type_hash(typename, distro)
        key += f"/{_mangle(name)}/{dds_type_name(typename)}/{hashed}/{qos_chunk(depth)}"
    parse_liveliness_token(key)
    return key


def parse_liveliness_token(key: str) -> LivelinessToken:
    """The entity a token key names; `RosMessageError` if it is not one. Stricter than
    rmw_zenoh's parser (which refuses only missing or empty chunks): names must be ROS names,
    and the zid, ids and QoS what rmw_zenoh writes, so a stray key is not taken for an entity."""
    parts = key.split("/") if isinstance(key, str) else []
    if len(parts) not in (9, 13) or parts[0] != LIVELINESS_PREFIX or parts[5] not in ENTITIES:
        raise RosMessageError(f"not an rmw_zenoh liveliness token: {key!r}")
    if not all(p.isascii() and p.isdigit() for p in parts[1:2] + parts[3:5]):
        raise RosMessageError(f"liveliness token with a non-numeric id: {key!r}")
    if (len(parts) == 9) != (parts[5] == "NN"):
        raise RosMessageError(f"liveliness token of the wrong length for {parts[5]}: {key!r}")
    if not (_ZID.fullmatch(parts[2]) and parts[6] and re.fullmatch(_TOKEN, parts[8])):
        raise RosMessageError(f"liveliness token with a bad zid, enclave or node name: {key!r}")
    head = (int(parts[1]), parts[2], int(parts[3]), int(parts[4]), parts[5])
    token = LivelinessToken(*head, _absolute(parts[7], key, root=True), parts[8])
    if len(parts) == 9:
        return token
    if not (_DDS_TYPE.fullmatch(parts[10]) and _HASH.fullmatch(parts[11])):
        raise RosMessageError(f"liveliness token with a bad type or hash: {key!r}")
    if not _QOS.fullmatch(parts[12]):
        raise RosMessageError(f"liveliness token with a bad QoS chunk: {key!r}")
    return token._replace(topic=_absolute(parts[9], key), typename=ros_type_name(parts[10]),
                          type_hash=parts[11], qos=parts[12])  # fmt: skip


def _absolute(chunk: str, key: str, root: bool = False) -> str:
    """A mangled chunk as the absolute ROS name it stands for ('/' itself only if ``root``)."""
    name = _demangle(chunk)
    if not ((root and name == "/") or (name.startswith("/") and _NAME.fullmatch(name))):
        raise RosMessageError(f"liveliness token with {chunk!r}, not an absolute ROS name: {key!r}")
    return name


# ---------------------------------------------------------------------------------------------
# The attachment of rmw_zenoh publications (also on service requests and replies).
#
# rmw_zenoh's AttachmentData::serialize_to_zbytes (attachment_helpers.cpp, since rolling 0.6.0,
# jazzy 0.2.4, humble 0.1.2 — "Change serialization format in attachment_helpers.cpp", #601 and
# backports) writes, with zenoh-cpp's ext::Serializer: int64 sequence_number, int64
# source_timestamp, std::array<uint8_t, 16> source_gid. Integers are little-endian; the array
# is a sequence, so a LEB128 length (one byte, 0x10) comes before the 16 bytes — 33 in all
# (design.md: "1 byte for the length of the publisher GID (currently always 16)"). Older
# releases wrote each value after its name as a string ("sequence_number", …); `parse_attachment`
# reads both.


@dataclass(frozen=True)
class Attachment:
    """Per-publication metadata: the publisher's sequence number (rmw_zenoh counts from 1), the
    source timestamp (ns since the UNIX epoch) and the publisher's GID (16 bytes)."""

    sequence_number: int
    source_timestamp: int
    source_gid: bytes

    def __post_init__(self) -> None:
        for name in ("sequence_number", "source_timestamp"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, int)
                or not -(2**63) <= value < 2**63
            ):
                raise RosMessageError(f"attachment {name} must be an int64, got {value!r}")
        try:
            gid = bytes(self.source_gid)
        except TypeError as exc:
            raise RosMessageError(f"attachment source_gid must be bytes: {exc}") from exc
        if len(gid) not in (GID_SIZE, 24):  # 24: rmw's RMW_GID_STORAGE_SIZE on Humble
            raise RosMessageError(f"attachment source_gid must be 16 bytes, got {len(gid)}")
        object.__setattr__(self, "source_gid", gid)


_LEGACY_KEYS = (b"sequence_number", b"source_timestamp", b"source_gid")


def encode_attachment(attachment: Attachment) -> bytes:
    """The 33 bytes rmw_zenoh (current releases) attaches to a publication."""
    a = attachment
    head = struct.pack("<qq", a.sequence_number, a.source_timestamp)
    return head + _leb128(len(a.source_gid)) + a.source_gid


def parse_attachment(data: bytes | bytearray | memoryview) -> Attachment:
    """An rmw_zenoh attachment, in the current layout or the older one with string keys;
    RosMessageError for anything else (including trailing bytes)."""
    buf = bytes(data)
    reader = _Reader(buf)
    if buf.startswith(_leb128(len(_LEGACY_KEYS[0])) + _LEGACY_KEYS[0]):
        values = []
        for key in _LEGACY_KEYS:
            if reader.take(reader.length()) != key:
                raise RosMessageError(f"attachment lacks its {key.decode()!r} key")
            values.append(reader.int64() if key != b"source_gid" else reader.take(reader.length()))
        seq, stamp, gid = values
    else:
        seq, stamp = reader.int64(), reader.int64()
        gid = reader.take(reader.length())
    if reader.pos != len(buf):
        raise RosMessageError(f"attachment has {len(buf) - reader.pos} trailing bytes")
    return Attachment(seq, stamp, gid)


def _leb128(n: int) -> bytes:
    """Unsigned LEB128 (zenoh-ext's VarInt for sequence and string lengths)."""
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


class _Reader:
    """Bounds-checked reads over an attachment; every shortfall is a RosMessageError."""

    def __init__(self, buf: bytes) -> None:
        self.buf, self.pos = buf, 0

    def take(self, n: int) -> bytes:
        if n > len(self.buf) - self.pos:
            raise RosMessageError(f"truncated attachment: {n} bytes wanted at {self.pos}")
        self.pos += n
        return self.buf[self.pos - n : self.pos]

    def int64(self) -> int:
        return struct.unpack("<q", self.take(8))[0]

    def length(self) -> int:
        n = 0
        for shift in range(0, 64, 7):
            byte = self.take(1)[0]
            n |= (byte & 0x7F) << shift
            if not byte & 0x80:
                return n
        raise RosMessageError("attachment length prefix is not a valid LEB128 integer")
