"""rosbag2 (Jazzy) bags in MCAP storage: write, inspect, read and repair them. No ROS import here.

A bag is a directory ``BAG/`` holding ``metadata.yaml`` (top key ``rosbag2_bagfile_information``,
version 9, storage ``mcap``) and ``BAG_0.mcap``: MCAP profile ``ros2``, one ``ros2msg`` schema per
type (the ``.msg`` text and its dependencies' texts), one ``cdr`` channel per topic carrying
``offered_qos_profiles`` and ``topic_type_hash``, Zstd chunks of 768 KiB, and at close a metadata
record ``rosbag2`` holding the same YAML as ``metadata.yaml`` without its top key. This is what
rosbag2 writes (see ROS_ON_PYPI.md), so ``ros2 bag info/play``, Foxglove and ``rosbags`` read these
bags, and ``cloth-sim info/play`` read theirs.

While recording, ``metadata.yaml`` holds a provisional entry (no messages) and the MCAP file has no
footer yet. A recorder that dies leaves both so: every complete chunk stays readable (chunks are
flushed to the file as they are finished), ``bag_info`` reports the bag as not closed, and
``reindex`` rewrites the readable part as a complete MCAP file and rebuilds ``metadata.yaml``,
keeping the originals.
"""

from __future__ import annotations

import datetime
import json
import os
import re
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import yaml
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

VERSION = 9
CHUNK_SIZE = 768 * 1024
MAGIC = b"\x89MCAP0\r\n"
INFINITE_NS = 2**63 - 1
DEFINITION_SEPARATOR = "\n" + "=" * 80 + "\n"
_BUILTIN_TYPES = {
    "bool",
    "byte",
    "char",
    "float32",
    "float64",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
    "string",
    "wstring",
}
# What parsing a damaged file raises varies (mcap's McapError, CRCValidationError, struct and zstd
# errors, unicode errors in names, …): any of them means "damaged here".
_MCAP_ERRORS = Exception


class BagError(Exception):
    """A bag that cannot be read or written; the message is one line naming the file and the
    fault."""


# --------------------------------------------------------------------------------------------- QoS
def qos_profiles_yaml(profiles: list[dict]) -> str:
    """The ``offered_qos_profiles`` string of metadata version 9 (string enums, ``{sec, nsec}``
    times)."""
    return (
        yaml.safe_dump(profiles, sort_keys=False, default_flow_style=False).strip()
        if profiles
        else ""
    )


def parse_qos_profiles(text) -> list[dict]:
    """The profiles of an ``offered_qos_profiles`` value (a YAML string, or a list in some
    writers)."""
    if not text:
        return []
    items = yaml.safe_load(text) if isinstance(text, str) else text
    if not isinstance(items, list) or not all(isinstance(p, dict) for p in items):
        raise ValueError("offered_qos_profiles is not a list of profiles")
    return items


def time_dict(ns: int) -> dict:
    return {"sec": int(ns) // 1_000_000_000, "nsec": int(ns) % 1_000_000_000}


def time_ns(d) -> int:
    return (
        int(d.get("sec", 0)) * 1_000_000_000 + int(d.get("nsec", 0)) if isinstance(d, dict) else 0
    )


# ----------------------------------------------------------------------------- message definitions
def interface_file(type_name: str, ext: str) -> Path | None:
    """Where ``pkg/msg/Type.<ext>`` is installed: under an AMENT_PREFIX_PATH prefix, or the
    ``share/`` beside the install prefix of the Python package ``pkg`` (a ROS install, the wheels'
    venv, or the package's own generated interfaces)."""
    pkg, sub, name = _split_type(type_name)
    rel = Path("share") / pkg / sub / f"{name}.{ext}"
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for entry in sys.path:
        if entry and (Path(entry) / pkg).is_dir():
            prefixes.extend(list(Path(entry).resolve().parents)[:4])
    prefixes.append(Path(sys.prefix))
    for prefix in prefixes:
        if (prefix / rel).is_file():
            return prefix / rel
    return None


def _split_type(type_name: str) -> tuple[str, str, str]:
    parts = type_name.split("/")
    if len(parts) == 2:
        return parts[0], "msg", parts[1]
    if len(parts) == 3:
        return parts[0], parts[1], parts[2]
    raise BagError(f"{type_name!r} is not a message type name (expected pkg/msg/Type)")


def _field_types(text: str, pkg: str) -> list[str]:
    """The non-builtin field types of a .msg text, as ``pkg/msg/Type``."""
    out = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        base = re.sub(r"\[.*\]$", "", line.split()[0])
        base = base.split("<=")[0]
        if base in _BUILTIN_TYPES:
            continue
        parts = base.split("/")
        out.append(f"{parts[0]}/msg/{parts[-1]}" if len(parts) > 1 else f"{pkg}/msg/{base}")
    return out


def message_definition(type_name: str) -> str:
    """The ``ros2msg`` schema rosbag2 stores: the type's .msg text, then each dependency's (depth
    first, once each) after a line of 80 '=' and ``MSG: pkg/Type``."""

    def text_of(t: str) -> str:
        path = interface_file(t, "msg")
        if path is None:
            raise BagError(f"no definition of {t} is installed (looked for share/{t}.msg)")
        return path.read_text()

    root = text_of(type_name)
    seen, parts = {type_name}, [root]

    def visit(text: str, pkg: str):
        for dep in _field_types(text, pkg):
            if dep in seen:
                continue
            seen.add(dep)
            dep_text = text_of(dep)
            dpkg, _, dname = _split_type(dep)
            parts.append(f"{DEFINITION_SEPARATOR}MSG: {dpkg}/{dname}\n{dep_text}")
            visit(dep_text, dpkg)

    visit(root, _split_type(type_name)[0])
    return "".join(parts)


def type_hash(type_name: str) -> str:
    """The type's RIHS01 hash from the ``.json`` rosidl installs beside the ``.msg`` ('' if
    none)."""
    path = interface_file(type_name, "json")
    if path is None:
        return ""
    try:
        for entry in json.loads(path.read_text()).get("type_hashes", []):
            if entry.get("type_name") == type_name:
                return str(entry.get("hash_string", ""))
    except (OSError, ValueError):
        pass
    return ""


# ------------------------------------------------------------------------------------------- model
@dataclass
class TopicInfo:
    name: str
    type: str
    count: int = 0
    offered_qos_profiles: str = ""
    type_hash: str = ""
    serialization_format: str = "cdr"


@dataclass
class FileInfo:
    path: Path
    size: int
    closed: bool
    message_count: int = 0
    start: int = 0  # log time of the first message (ns)
    end: int = 0  # log time of the last message (ns)
    chunks: int = 0
    compression: set = field(default_factory=set)
    topics: dict = field(default_factory=dict)  # channel topic -> TopicInfo (this file)
    fault: str = ""  # why reading stopped early (unclosed files)


@dataclass
class BagInfo:
    path: Path
    files: list[FileInfo]
    metadata: dict | None  # metadata.yaml's rosbag2_bagfile_information (None: bare MCAP)

    @property
    def closed(self) -> bool:
        return all(f.closed for f in self.files)

    @property
    def topics(self) -> list[TopicInfo]:
        merged: dict[str, TopicInfo] = {}
        for f in self.files:
            for t in f.topics.values():
                m = merged.setdefault(
                    t.name,
                    TopicInfo(
                        t.name,
                        t.type,
                        0,
                        t.offered_qos_profiles,
                        t.type_hash,
                        t.serialization_format,
                    ),
                )
                m.count += t.count
        return list(merged.values())

    @property
    def message_count(self) -> int:
        return sum(f.message_count for f in self.files)

    @property
    def start(self) -> int:
        starts = [f.start for f in self.files if f.message_count]
        return min(starts) if starts else 0

    @property
    def end(self) -> int:
        ends = [f.end for f in self.files if f.message_count]
        return max(ends) if ends else 0

    @property
    def size(self) -> int:
        return sum(f.size for f in self.files)


def metadata_dict(
    files: list[FileInfo], topics: list[TopicInfo], base: Path, ros_distro: str | None = None
) -> dict:
    """metadata.yaml's ``rosbag2_bagfile_information`` (version 9) for these files and topics."""
    info = BagInfo(base, files, None)
    start, end = info.start, info.end
    return {
        "version": VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": end - start},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": info.message_count,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": t.serialization_format,
                    "offered_qos_profiles": t.offered_qos_profiles,
                    "type_description_hash": t.type_hash,
                },
                "message_count": t.count,
            }
            for t in topics
        ],
        # the chunks are compressed by the MCAP storage itself, not by rosbag2's compressor
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f.path.name for f in files],
        "files": [
            {
                "path": f.path.name,
                "starting_time": {"nanoseconds_since_epoch": f.start},
                "duration": {"nanoseconds": f.end - f.start},
                "message_count": f.message_count,
            }
            for f in files
        ],
        "custom_data": None,
        "ros_distro": ros_distro or os.environ.get("ROS_DISTRO", "jazzy"),
    }


def _dump_yaml(data) -> str:
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False, width=1 << 16)


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


# ------------------------------------------------------------------------------------------ writer
class BagWriter:
    """Writes one rosbag2 bag directory (a single MCAP file; no splitting).

    ``add_topic`` registers a topic (schema + channel); ``write`` adds one message's CDR bytes;
    ``close`` writes the ``rosbag2`` metadata record, the MCAP summary and ``metadata.yaml``. Every
    finished chunk is handed to the OS at once, so a killed writer loses at most the chunk it was
    filling.
    """

    def __init__(self, path, overwrite: bool = False, chunk_size: int = CHUNK_SIZE):
        self.path = Path(path)
        if self.path.exists() or self.path.is_symlink():
            if not overwrite:
                raise BagError(f"{self.path} already exists (use --overwrite to replace it)")
            _remove_bag(self.path)
        self.path.mkdir(parents=True)
        self.file_path = self.path / f"{self.path.name}_0.mcap"
        self._file = open(self.file_path, "wb")
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="cloth_sim")
        self._schemas: dict[str, int] = {}
        self.topics: dict[int, TopicInfo] = {}
        self.start = self.end = 0
        self.message_count = 0
        self.bytes_written = 0
        self._closed = False
        _write_atomically(
            self.path / "metadata.yaml",
            _dump_yaml(
                {
                    "rosbag2_bagfile_information": metadata_dict(
                        [FileInfo(self.file_path, 0, False)], [], self.path
                    )
                }
            ),
        )

    def add_topic(
        self,
        name: str,
        type_name: str,
        qos_profiles: list[dict] | str = (),
        topic_type_hash: str | None = None,
        definition: str | None = None,
    ) -> int:
        if type_name not in self._schemas:
            text = definition if definition is not None else message_definition(type_name)
            self._schemas[type_name] = self._writer.register_schema(
                type_name, "ros2msg", text.encode()
            )
        qos = (
            qos_profiles
            if isinstance(qos_profiles, str)
            else qos_profiles_yaml(list(qos_profiles))
        )
        digest = type_hash(type_name) if topic_type_hash is None else topic_type_hash
        cid = self._writer.register_channel(
            name,
            "cdr",
            self._schemas[type_name],
            {"offered_qos_profiles": qos, "topic_type_hash": digest},
        )
        self.topics[cid] = TopicInfo(name, type_name, 0, qos, digest)
        return cid

    def write(
        self,
        channel_id: int,
        log_time: int,
        data: bytes,
        publish_time: int | None = None,
        sequence: int = 0,
    ) -> None:
        self._writer.add_message(
            channel_id,
            int(log_time),
            data,
            int(log_time if publish_time is None else publish_time),
            int(sequence),
        )
        self._file.flush()  # a finished chunk goes to the OS now, not at close
        topic = self.topics[channel_id]
        topic.count += 1
        if self.message_count == 0 or log_time < self.start:
            self.start = int(log_time)
        self.end = max(self.end, int(log_time))
        self.message_count += 1
        self.bytes_written += len(data)

    def close(self) -> dict:
        """Finish the MCAP file and metadata.yaml; returns the metadata written. Idempotent."""
        if self._closed:
            return self.metadata
        self._closed = True
        f = FileInfo(self.file_path, 0, True, self.message_count, self.start, self.end)
        self.metadata = _finish_mcap(self._writer, f, list(self.topics.values()), self.path)
        self._file.close()
        _write_atomically(
            self.path / "metadata.yaml", _dump_yaml({"rosbag2_bagfile_information": self.metadata})
        )
        return self.metadata


def _finish_mcap(writer: Writer, info: FileInfo, topics: list[TopicInfo], base: Path) -> dict:
    """Close an MCAP file as rosbag2 does: the ``rosbag2`` metadata record (metadata.yaml's content
    without its top key), then the summary. Returns that metadata."""
    meta = metadata_dict([info], topics, base)
    writer.add_metadata("rosbag2", {"serialized_metadata": _dump_yaml(meta).strip()})
    writer.finish()
    return meta


def _remove_bag(path: Path) -> None:
    """Delete an existing bag for --overwrite, refusing anything that does not look like one."""
    if path.is_dir():
        entries = list(path.iterdir())
        if (
            entries
            and not (path / "metadata.yaml").exists()
            and not any(p.suffix == ".mcap" for p in entries)
        ):
            raise BagError(
                f"{path} exists and is not a bag (no metadata.yaml or .mcap); not replacing it"
            )
        shutil.rmtree(path)
    else:
        raise BagError(f"{path} exists and is not a directory; not replacing it")


# ------------------------------------------------------------------------------------------ reader
def bag_files(path) -> tuple[Path, list[Path], dict | None]:
    """(bag path, its MCAP files in order, metadata or None for a bare .mcap); BagError if
    unusable."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such bag (neither a directory nor a file)")
    if path.is_file():
        _check_magic(path)
        return path, [path], None
    meta_path = path / "metadata.yaml"
    if not meta_path.is_file():
        hint = (
            " — it holds MCAP files: `cloth-sim reindex` rebuilds metadata.yaml from them"
            if any(path.glob("*.mcap"))
            else ""
        )
        raise BagError(f"{path}: no metadata.yaml, so not a rosbag2 bag directory{hint}")
    meta = read_metadata(meta_path)
    files = [path / rel for rel in meta["relative_file_paths"]]
    for f in files:
        if not f.is_file():
            raise BagError(f"{meta_path}: relative_file_paths names {f.name}, which is missing")
        _check_magic(f)
    return path, files, meta


def read_metadata(meta_path: Path) -> dict:
    try:
        doc = yaml.safe_load(meta_path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as e:
        raise BagError(f"{meta_path}: not valid YAML ({str(e).splitlines()[0]})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("rosbag2_bagfile_information"), dict):
        raise BagError(f"{meta_path}: no rosbag2_bagfile_information mapping at the top")
    meta = doc["rosbag2_bagfile_information"]
    storage = meta.get("storage_identifier")
    if storage != "mcap":
        raise BagError(
            f"{meta_path}: storage_identifier is {storage!r}; only 'mcap' bags are supported"
        )
    files = meta.get("relative_file_paths")
    if not isinstance(files, list) or not files or not all(isinstance(f, str) for f in files):
        raise BagError(f"{meta_path}: relative_file_paths must be a non-empty list of file names")
    if not isinstance(meta.get("version"), int) or not 1 <= meta["version"] <= VERSION:
        raise BagError(
            f"{meta_path}: version {meta.get('version')!r} is not one this reader knows "
            f"(1..{VERSION})"
        )
    return meta


def _check_magic(path: Path) -> None:
    size = path.stat().st_size
    if size == 0:
        raise BagError(f"{path}: empty file (0 bytes), not an MCAP file")
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
    if len(head) < len(MAGIC) and MAGIC.startswith(head):
        raise BagError(f"{path}: truncated to {len(head)} bytes, before the end of the MCAP magic")
    if head != MAGIC:
        raise BagError(f"{path}: not an MCAP file (it does not start with the MCAP magic bytes)")


def file_info(path: Path) -> FileInfo:
    """What one MCAP file holds: from its summary when it was closed, else by reading it up to the
    last complete record (an unclosed file)."""
    size = path.stat().st_size
    if _is_closed(path):
        try:
            with open(path, "rb") as f:
                summary = make_reader(f).get_summary()
        except _MCAP_ERRORS as e:
            raise BagError(
                f"{path}: corrupt MCAP summary ({_describe(e)}); `cloth-sim reindex` can "
                f"rebuild it from the chunks"
            ) from None
        if summary is None or summary.statistics is None:
            raise BagError(
                f"{path}: the MCAP file has a footer but no statistics; run `cloth-sim reindex`"
            )
        st = summary.statistics
        info = FileInfo(
            path,
            size,
            True,
            st.message_count,
            st.message_start_time,
            st.message_end_time,
            st.chunk_count,
            {c.compression or "none" for c in summary.chunk_indexes},
        )
        for cid, ch in summary.channels.items():
            schema = summary.schemas.get(ch.schema_id)
            info.topics[cid] = _topic_of(ch, schema, st.channel_message_counts.get(cid, 0))
        return info
    info = FileInfo(path, size, False)
    for _ in _scan(path, info):
        pass
    return info


def _is_closed(path: Path) -> bool:
    """Whether the file ends with the closing MCAP magic (after its footer): a writer finished
    it."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        f.seek(max(0, size - len(MAGIC)))
        return size > 2 * len(MAGIC) and f.read() == MAGIC


def _topic_of(ch: Channel, schema: Schema | None, count: int) -> TopicInfo:
    return TopicInfo(
        ch.topic,
        schema.name if schema else "",
        count,
        ch.metadata.get("offered_qos_profiles", ""),
        ch.metadata.get("topic_type_hash", ""),
        ch.message_encoding,
    )


def _describe(e: BaseException) -> str:
    text = str(e).splitlines()[0] if str(e) else ""
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def _scan(path: Path, info: FileInfo, strict: bool = False) -> Iterator:
    """Read a file record by record, chunk CRCs checked, filling ``info``; yields its Schema,
    Channel and Message records in file order. Stops quietly at the first incomplete or damaged
    record of an unclosed file (``info.fault`` says which); with ``strict`` (a closed file) a
    damaged record raises BagError."""
    schemas: dict[int, Schema] = {}
    with open(path, "rb") as f:
        records = StreamReader(f, emit_chunks=True).records
        while True:
            offset = f.tell()
            try:
                record = next(records)
                inner = _chunk_records(record) if isinstance(record, Chunk) else [record]
            except StopIteration:
                return
            except _MCAP_ERRORS as e:
                info.fault = f"{_describe(e)} in the record at byte {offset}"
                if strict:
                    raise BagError(f"{path}: corrupt data ({info.fault})") from None
                return
            if isinstance(record, Chunk):
                info.chunks += 1
                info.compression.add(record.compression or "none")
            for r in inner:
                if isinstance(r, Schema):
                    schemas[r.id] = r
                elif isinstance(r, Channel):
                    info.topics.setdefault(r.id, _topic_of(r, schemas.get(r.schema_id), 0))
                elif isinstance(r, Message):
                    topic = info.topics.get(r.channel_id)
                    if topic is None:
                        continue
                    topic.count += 1
                    info.start = (
                        r.log_time if info.message_count == 0 else min(info.start, r.log_time)
                    )
                    info.end = max(info.end, r.log_time)
                    info.message_count += 1
                else:
                    continue
                yield r
            if isinstance(record, (DataEnd, Footer)):  # the summary repeats schemas and channels
                return


def _chunk_records(chunk: Chunk) -> list:
    """A chunk's records, checking its CRC, so a damaged chunk is refused whole."""
    return breakup_chunk(chunk, validate_crc=True)


def bag_info(path) -> BagInfo:
    path, files, meta = bag_files(path)
    return BagInfo(path, [file_info(f) for f in files], meta)


def iter_messages(path, topics: set[str] | None = None) -> Iterator[tuple[TopicInfo, Message]]:
    """Every readable message of the bag in file order (log-time order for bags rosbag2 or
    cloth-sim wrote), as (topic, mcap Message). A damaged chunk of a closed file raises BagError;
    an unclosed file ends at its last complete chunk."""
    _, files, _ = bag_files(path)
    for f in files:
        closed = _is_closed(f)
        info = FileInfo(f, f.stat().st_size, closed)
        for r in _scan(f, info, strict=closed):
            if isinstance(r, Message):
                topic = info.topics[r.channel_id]
                if topics is None or topic.name in topics:
                    yield topic, r


# ----------------------------------------------------------------------------------------- reindex
def reindex(path) -> list[str]:
    """Make an unclosed bag whole: rewrite each unclosed MCAP file from its complete chunks (the
    original kept as ``<name>.unclosed``) and rebuild metadata.yaml (the old one kept as
    ``metadata.yaml.orig``). Returns what was done, one line each."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such bag (neither a directory nor a file)")
    if path.is_file():
        files, base = [path], None
    else:
        base = path
        try:
            _, files, _ = bag_files(path)
        except BagError:
            files = sorted(path.glob("*.mcap"), key=_split_index)
            if not files:
                raise BagError(
                    f"{path}: no metadata.yaml and no .mcap files, nothing to reindex"
                ) from None
        for f in files:
            _check_magic(f)
    done = []
    infos = []
    for f in files:
        if not _is_closed(f):  # (file_info would scan the whole file that _rewrite reads)
            backup = f.with_name(f.name + ".unclosed")
            if backup.exists():
                raise BagError(f"{backup} already exists; move it away before reindexing")
            tmp = f.with_name(f.name + ".reindexing")
            count = _rewrite(f, tmp)
            os.replace(f, backup)
            os.replace(tmp, f)
            done.append(
                f"{f.name}: rewrote {count} messages from the complete chunks "
                f"(original kept as {backup.name})"
            )
        infos.append(file_info(f))
    if base is not None:
        meta_path = base / "metadata.yaml"
        topics = BagInfo(base, infos, None).topics
        new = {"rosbag2_bagfile_information": metadata_dict(infos, topics, base)}
        if meta_path.exists():
            backup = base / "metadata.yaml.orig"
            if not backup.exists():
                shutil.copy2(meta_path, backup)
        _write_atomically(meta_path, _dump_yaml(new))
        done.append(
            f"metadata.yaml: {new['rosbag2_bagfile_information']['message_count']} messages "
            f"on {len(topics)} topics"
        )
    return done


def _split_index(p: Path) -> int:
    m = re.search(r"_(\d+)\.mcap$", p.name)
    return int(m.group(1)) if m else 0


def _rewrite(src: Path, dst: Path) -> int:
    """Copy every readable schema, channel and message of ``src`` into a complete MCAP file
    ``dst``; returns the number of messages copied."""
    info = FileInfo(src, src.stat().st_size, False)
    with open(dst, "wb") as out:
        w = Writer(out, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="cloth_sim reindex")
        schema_ids, channel_ids = {0: 0}, {}
        for r in _scan(src, info):
            if isinstance(r, Schema):
                schema_ids[r.id] = w.register_schema(r.name, r.encoding, r.data)
            elif isinstance(r, Channel):
                channel_ids[r.id] = w.register_channel(
                    r.topic, r.message_encoding, schema_ids.get(r.schema_id, 0), dict(r.metadata)
                )
            elif r.channel_id in channel_ids:
                w.add_message(
                    channel_ids[r.channel_id], r.log_time, r.data, r.publish_time, r.sequence
                )
        _finish_mcap(
            w,
            FileInfo(dst, 0, True, info.message_count, info.start, info.end),
            list(info.topics.values()),
            dst.parent,
        )
    return info.message_count


# -------------------------------------------------------------------------------------------- info
def _stamp(ns: int) -> str:
    t = datetime.datetime.fromtimestamp(ns // 1_000_000_000, datetime.timezone.utc)
    sec, nsec = divmod(ns, 1_000_000_000)
    return f"{t:%b %d %Y %H:%M:%S}.{nsec:09d} UTC ({sec}.{nsec:09d})"


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{n} B"
        n /= 1024
    return f"{n} B"


def format_info(info: BagInfo) -> str:
    """``ros2 bag info``'s layout, plus the MCAP chunk compression and whether the bag was
    closed."""
    w = 19
    lines = [f"{'Files:':<{w}}{info.files[0].path.name}"]
    lines += [f"{'':<{w}}{f.path.name}" for f in info.files[1:]]
    distro = (info.metadata or {}).get("ros_distro", "")
    chunks = sum(f.chunks for f in info.files)
    compression = sorted(set().union(*(f.compression for f in info.files)) - {"none"}) or ["none"]
    lines += [
        f"{'Bag size:':<{w}}{_size(info.size)}",
        f"{'Storage id:':<{w}}mcap",
        f"{'ROS Distro:':<{w}}{distro or 'unknown'}",
        f"{'Duration:':<{w}}{(info.end - info.start) / 1e9:.9f}s",
        f"{'Start:':<{w}}{_stamp(info.start)}",
        f"{'End:':<{w}}{_stamp(info.end)}",
        f"{'Messages:':<{w}}{info.message_count}",
        f"{'Compression:':<{w}}{', '.join(compression)} (MCAP chunks: {chunks})",
    ]
    topics = info.topics
    if not topics:
        lines.append(f"{'Topic information:':<{w}}(none)")
    for i, t in enumerate(topics):
        head = "Topic information:" if i == 0 else ""
        lines.append(
            f"{head:<{w}}Topic: {t.name} | Type: {t.type} | Count: {t.count} | "
            f"Serialization Format: {t.serialization_format}"
        )
    if info.closed:
        status = "closed"
        if info.metadata is not None and info.metadata.get("message_count") != info.message_count:
            status += (
                f"; but metadata.yaml says {info.metadata.get('message_count')} messages: "
                f"`cloth-sim reindex` rewrites it"
            )
    else:
        bad = [f for f in info.files if not f.closed]
        status = (
            "NOT CLOSED (its recorder did not finish): "
            + "; ".join(
                f"{f.path.name} readable up to its last complete chunk ({f.chunks} chunks, "
                f"{f.message_count} messages)"
                for f in bad
            )
            + " — `cloth-sim reindex` makes it whole"
        )
    lines.append(f"{'Status:':<{w}}{status}")
    return "\n".join(lines)
