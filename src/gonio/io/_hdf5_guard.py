"""Reading untrusted HDF5 (native ``*.brdf.h5``) through a bounded path.

libhdf5 trusts the structures it reads: a corrupt B-tree or heap can make it re-read the same
blocks for minutes without returning to Python (so Ctrl-C is not seen), a dataset can declare
gigabytes that are never stored (unallocated chunks read as the fill value), point at external
files such as ``/dev/zero``, or be a virtual dataset assembled from other files. Four defences:

* :func:`check_global_heaps` (after the dataset checks, before any attribute is read):
  libhdf5 decodes a global heap collection (where variable-length
  strings such as gonio's attributes live) by stepping from object to object; an object with
  index 0 and size 0 makes that step zero and the library loops forever in C, without reading
  and without seeing Ctrl-C (a 1 KB duplicated range in a scattered file does exactly this).
  Every collection in the file is walked the same way first, and a step that does not advance
  or leaves the collection is an error;
* :class:`BoundedReader`: the file is opened through h5py's file-object driver on a reader that
  counts every read. More than :data:`READ_FACTOR` times the file size (plus
  :data:`READ_SLACK_BYTES`), or more than :data:`MAX_READ_CALLS` reads, raise inside libhdf5,
  which unwinds with an error; the Python callback also lets a pending Ctrl-C through.
* :func:`check_dataset`: before any data is read, a dataset must have the documented layout
  (contiguous, compact or chunked; no external storage; not virtual), only the documented
  filters (shuffle, deflate, fletcher32), a declared size within the memory budget
  :data:`gonio._bounded.MAX_DECODED_BYTES`, its storage fully allocated inside the file, and no
  chunk may expand by more than :data:`gonio._bounded.MAX_COMPRESSION_RATIO`.
* :func:`check_attribute`: an attribute's declared size is bounded before it is read.
"""

from __future__ import annotations

import io
import math
import os
from typing import Any

from gonio._bounded import MAX_COMPRESSION_RATIO, MAX_DECODED_BYTES
from gonio.io._common import PathLike, fail

#: A reader may read at most this many times the file's size in total (plus the slack).
READ_FACTOR = 16
READ_SLACK_BYTES = 64 << 20
#: Most read calls one open file may make (a legitimate table file needs a few hundred).
MAX_READ_CALLS = 200_000
#: HDF5 filter ids a native file may use: deflate (1), shuffle (2), fletcher32 (3).
ALLOWED_FILTERS = {1: "deflate", 2: "shuffle", 3: "fletcher32"}
#: Largest attribute (declared elements x element size) read from a file.
MAX_ATTRIBUTE_BYTES = 16 << 20
#: Most chunks one dataset may have (the writer's chunks are about 256 KiB each).
MAX_CHUNKS = 1 << 16


_GCOL = b"GCOL\x01"  # global heap collection signature and version


def _size_of_lengths(head: bytes) -> int:
    """The "size of lengths" field of the HDF5 superblock at offset 0 (versions 0-3)."""
    version = head[8] if len(head) > 8 else -1
    pos = {0: 14, 1: 14, 2: 10, 3: 10}.get(version)
    if pos is None or len(head) <= pos or head[pos] not in (2, 4, 8):
        raise ValueError(f"unknown HDF5 superblock (version {version})")
    return head[pos]


def _gaps(raw_data: list[tuple[int, int]], size: int) -> list[tuple[int, int]]:
    """The byte ranges of ``[0, size)`` not covered by ``raw_data``."""
    gaps, pos = [], 0
    for start, end in sorted(raw_data):
        if start > pos:
            gaps.append((pos, start))
        pos = max(pos, end)
    if pos < size:
        gaps.append((pos, size))
    return gaps


def check_global_heaps(
    path: PathLike, raw_data: list[tuple[int, int]] = (), data: bytes | None = None
) -> None:
    """Walk every global heap collection as libhdf5's decoder does; refuse one it would loop on.

    Collections are found by their signature outside the datasets' raw data (``raw_data``: byte
    ranges ``[start, end)`` from :func:`check_group_datasets`; a payload that happens to spell
    the signature is not a heap, and skipping the payload keeps the scan to the metadata) and
    outside collections already walked.

    The walk (HDF5 file format spec, "Global Heap"): after the 16-byte header, each object has
    a header of index (2 bytes), reference count (2), reserved (4) and size (``L`` bytes, the
    superblock's size of lengths), then its data padded to 8 bytes; index 0 is the free space,
    whose size is the rest of the collection; a tail too short for an object header is free.

    ``data``: the file's bytes when it is held in memory (a member of an archive); ``path``
    then only names it in messages.
    """
    import mmap

    if data is not None:
        _walk_heaps(data, list(raw_data), path)
        return
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        _walk_heaps(mm, list(raw_data), path)


def _walk_heaps(data: Any, raw_data: list[tuple[int, int]], path: PathLike) -> None:
    """:func:`check_global_heaps` on the file's bytes (``bytes`` or an ``mmap``)."""
    try:
        n_len = _size_of_lengths(data[:16])
    except ValueError as exc:
        raise fail(path, str(exc)) from None
    done = 0  # end of the last collection walked
    for lo, hi in _gaps(raw_data, len(data)):
        at = data.find(_GCOL, max(lo, done), hi)
        while at >= 0:
            done = _walk_collection(data, at, n_len, path)
            at = data.find(_GCOL, done, hi) if done < hi else -1


def _walk_collection(data: Any, at: int, n_len: int, path: PathLike) -> int:
    """Walk the collection at byte ``at`` (see :func:`check_global_heaps`); returns its end."""
    hdr = obj_hdr = 8 + n_len
    size = len(data)
    if at + hdr > size:
        raise fail(path, f"global heap collection at byte {at} is truncated")
    end = at + int.from_bytes(data[at + 8 : at + 8 + n_len], "little")
    if not at + hdr <= end <= size:
        raise fail(path, f"global heap collection at byte {at} has an impossible size")
    p = at + hdr
    while p < end:
        if p + obj_hdr > end:
            break  # free space too small for an object header
        idx = int.from_bytes(data[p : p + 2], "little")
        obj = int.from_bytes(data[p + 8 : p + 8 + n_len], "little")
        need = obj_hdr + -(-obj // 8) * 8 if idx > 0 else obj
        if need <= 0 or p + need > end:
            raise fail(
                path,
                f"corrupt global heap collection at byte {at}: object {idx} at byte {p} has "
                f"size {obj} (the HDF5 library would loop or overrun on it)",
            )
        p += need
    return end


class ReadBudgetExceeded(OSError):
    """Raised from inside libhdf5's reads when a file is being read far more than its size."""


class BoundedReader(io.RawIOBase):
    """A read-only raw file that refuses to read more than its budget (see module docstring);
    ``source`` is a path, or the file's bytes when it is held in memory."""

    def __init__(self, source: PathLike | bytes) -> None:
        super().__init__()
        if isinstance(source, bytes):
            self._fh: Any = io.BytesIO(source)
            self.size = len(source)
        else:
            self._fh = open(source, "rb")
            self.size = os.fstat(self._fh.fileno()).st_size
        self.budget = READ_FACTOR * self.size + READ_SLACK_BYTES
        self.bytes_read = 0
        self.calls = 0
        self.exceeded: str | None = None

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._fh.seek(offset, whence)

    def tell(self) -> int:
        return self._fh.tell()

    def readinto(self, buf: Any) -> int:
        self.calls += 1
        if self.calls > MAX_READ_CALLS:
            self.exceeded = f"more than {MAX_READ_CALLS} reads"
        elif self.bytes_read + len(buf) > self.budget:
            self.exceeded = f"more than {self.budget} bytes read from a {self.size}-byte file"
        if self.exceeded:
            raise ReadBudgetExceeded(self.exceeded)
        n = self._fh.readinto(buf)
        self.bytes_read += n
        return n

    def close(self) -> None:
        self._fh.close()
        super().close()


def open_bounded(source: PathLike | bytes) -> Any:
    """``h5py.File`` opened read-only on a :class:`BoundedReader` of ``source`` (a path or the
    file's bytes)."""
    import h5py

    reader = BoundedReader(source)
    try:
        h5 = h5py.File(reader, "r")
    except BaseException:
        reader.close()
        raise
    h5._gonio_reader = reader  # kept alive with the file; closed by close_bounded
    return h5


def close_bounded(h5: Any) -> None:
    """Close a file from :func:`open_bounded` and its reader."""
    reader = getattr(h5, "_gonio_reader", None)
    try:
        h5.close()
    finally:
        if reader is not None:
            reader.close()


def budget_problem(h5: Any) -> str | None:
    """Why the reader of ``h5`` stopped reading, or None."""
    reader = getattr(h5, "_gonio_reader", None)
    return None if reader is None else reader.exceeded


def check_attribute(obj: Any, name: str, path: PathLike) -> None:
    """Refuse an attribute whose declared size exceeds :data:`MAX_ATTRIBUTE_BYTES`."""
    import h5py

    aid = h5py.h5a.open(obj.id, name.encode("utf-8"))
    n = math.prod(aid.shape or ())
    if n * max(1, aid.dtype.itemsize) > MAX_ATTRIBUTE_BYTES:
        raise fail(path, f"attribute {name!r} on {obj.name} declares {n} elements")


def check_dataset(ds: Any, path: PathLike, file_size: int) -> list[tuple[int, int]]:
    """Refuse a dataset that is not stored the documented way (see the module docstring).

    Called before any of the dataset's data is read; it looks at metadata only. Returns the
    byte ranges ``[start, end)`` of the file that hold the dataset's raw data.
    """
    import h5py

    name = ds.name
    dcpl = ds.id.get_create_plist()
    layout = dcpl.get_layout()
    if layout == h5py.h5d.VIRTUAL:
        raise fail(path, f"{name} is a virtual dataset (not allowed in a native file)")
    if layout not in (h5py.h5d.CONTIGUOUS, h5py.h5d.CHUNKED, h5py.h5d.COMPACT):
        raise fail(path, f"{name} has an unknown storage layout {layout}")
    if dcpl.get_external_count():
        raise fail(path, f"{name} uses external storage (not allowed in a native file)")
    filters = [dcpl.get_filter(i)[0] for i in range(dcpl.get_nfilters())]
    bad = [f for f in filters if f not in ALLOWED_FILTERS]
    if bad:
        allowed = ", ".join(ALLOWED_FILTERS.values())
        raise fail(path, f"{name} uses HDF5 filter {bad[0]} (allowed: {allowed})")
    if ds.dtype.kind not in "fiub" or ds.dtype.itemsize > 8:
        raise fail(path, f"{name} has dtype {ds.dtype}, not a plain number type")
    shape = tuple(int(s) for s in ds.shape)
    nbytes = math.prod(shape) * ds.dtype.itemsize
    if nbytes > MAX_DECODED_BYTES:
        raise fail(
            path,
            f"{name} declares {shape} ({nbytes / 2**20:.0f} MiB), over the "
            f"{MAX_DECODED_BYTES >> 20} MiB a table may take",
        )
    if nbytes == 0:
        return []
    if layout == h5py.h5d.CONTIGUOUS:
        offset = ds.id.get_offset()
        stored = ds.id.get_storage_size()
        if offset is None or stored < nbytes or offset + nbytes > file_size:
            raise fail(path, f"{name}: data not stored in the file ({stored} of {nbytes} bytes)")
        return [(offset, offset + stored)]
    if layout == h5py.h5d.COMPACT:
        return []  # stored inside the object header, which is inside the file
    chunk = tuple(int(c) for c in dcpl.get_chunk())
    if len(chunk) != len(shape) or min(chunk) < 1:
        raise fail(path, f"{name}: bad chunk shape {chunk}")
    expected = math.prod(-(-s // c) for s, c in zip(shape, chunk, strict=True))
    if expected > MAX_CHUNKS:
        raise fail(path, f"{name}: {expected} chunks (chunks of {chunk} are too small)")
    n_chunks = ds.id.get_num_chunks()
    if n_chunks != expected:
        raise fail(path, f"{name}: {n_chunks} of {expected} chunks stored (missing data)")
    chunk_bytes = math.prod(chunk) * ds.dtype.itemsize
    min_stored = chunk_bytes / MAX_COMPRESSION_RATIO
    extents = []
    for i in range(n_chunks):
        info = ds.id.get_chunk_info(i)
        if info.byte_offset is None or info.byte_offset + info.size > file_size:
            raise fail(path, f"{name}: chunk {i} lies outside the file")
        if info.size < min_stored:
            raise fail(
                path,
                f"{name}: chunk {i} expands {info.size} bytes to {chunk_bytes} "
                f"(more than {MAX_COMPRESSION_RATIO}:1)",
            )
        extents.append((info.byte_offset, info.byte_offset + info.size))
    return extents


def check_group_datasets(group: Any, path: PathLike, file_size: int) -> list[tuple[int, int]]:
    """:func:`check_dataset` on every dataset in ``group`` and its sub-groups; all of them
    together may declare at most :data:`gonio._bounded.MAX_DECODED_BYTES`. Returns the byte
    ranges of their raw data (for :func:`check_global_heaps`)."""
    import h5py

    datasets = []
    stack = [group]
    while stack:
        g = stack.pop()
        for key in g:
            link = g.get(key, getlink=True)
            if not isinstance(link, h5py.HardLink):
                raise fail(path, f"{g.name}/{key} is a {type(link).__name__} (not allowed)")
            obj = g[key]
            if isinstance(obj, h5py.Dataset):
                datasets.append(obj)
            elif isinstance(obj, h5py.Group) and obj.name.count("/") < 8:
                stack.append(obj)
    total = sum(math.prod(ds.shape or ()) * ds.dtype.itemsize for ds in datasets)
    if total > MAX_DECODED_BYTES:
        raise fail(
            path,
            f"datasets declare {total / 2**20:.0f} MiB in total, over the "
            f"{MAX_DECODED_BYTES >> 20} MiB a file may take",
        )
    return [e for ds in datasets for e in check_dataset(ds, path, file_size)]
