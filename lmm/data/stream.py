"""Append-only output files that are valid whenever they exist: the live recordings (BVH and input CSV).

A stream is not written whole, so :mod:`lmm.data.atomic` does not fit it. Instead :class:`StreamFile`
keeps these rules, which hold after a ``kill -9`` at any moment and on a full disk:

* **No file without data.** Nothing appears under the file's name until the first chunk of records is
  written: the header and that chunk go to a hidden temporary file beside it (``.NAME.PID.partial``),
  are fsynced and then renamed (or, with ``overwrite=False``, hard-linked) to the name. A stream
  closed with no record leaves nothing behind, and a kill before the first chunk leaves at most the
  hidden temporary file, never a header-only file under the name. Whether the folder can be written is
  checked when the stream is opened (a probe file created and removed at once), so a read-only or
  missing folder is an error at the start, not minutes later.
* **Whole records only.** Records are appended in chunks; a failed write (``ENOSPC``, ``EFBIG``, ``EIO``)
  truncates the file back to its last complete chunk, so a full disk leaves the file as it was after
  the last good chunk, and raises :class:`StreamWriteError` (an ``OSError`` naming the file and how
  much it kept). The stream is closed after that; closing it again raises nothing.
* **A count in the header matches.** A header may hold a fixed-width count field (BVH's ``Frames:``,
  see :func:`lmm.data.bvh.frames_field`); after each appended chunk it is rewritten in place and the
  file fsynced. Between the append and the rewrite (two consecutive system calls, once per flush) the
  count is lower than the frames present; :func:`repair_count` fixes such a file (and a partial last
  line a kill inside a ``write`` can leave).
* **No partial line after a kill** (``page_lines``, the BVH recordings). Linux stops a ``write`` to a
  file at a page boundary when the process is killed, so a chunk written in one call can end up cut
  inside a line. With ``page_lines`` an appended chunk is laid out so that no line crosses a page
  boundary of the file (a line that would is moved to the next page, after spaces: leading blanks that
  line readers split away) and is written one page at a time, each ``pwrite`` inside one page: a kill
  leaves whole lines, possibly followed by blanks. Lines longer than a page are written as they are.
"""
from __future__ import annotations

import errno
import mmap
import os
from pathlib import Path

from lmm.data.atomic import replace_regular

PAGE = mmap.PAGESIZE


class StreamWriteError(OSError):
    """A write to a stream failed; the file keeps its last complete chunk (or does not exist).
    ``str(e)`` is one line: ``PATH: <reason>; <what the file keeps>``."""

    def __str__(self) -> str:
        return f"{self.filename}: {self.strerror}"


class StreamFile:
    """An append-only file of ``header`` + records (see the module doc).

    ``count_offset`` / ``format_count``: where in ``header`` (a byte offset) the record count field
    sits and how a count is written there (same width every time); ``None`` for no count (CSV).
    ``unit``: what a record is called in error messages.
    ``overwrite``: replace an existing file of the same name at the first chunk (``run --record``);
    with ``False`` an existing name is refused at the start (the studio never overwrites a file).
    ``page_lines``: records are lines that may carry leading blanks; appended chunks keep every line
    inside one page (see the module doc).
    """

    def __init__(self, path, header: bytes, *, count_offset: int | None = None, format_count=None,
                 overwrite: bool = True, unit: str = "records", page_lines: bool = False):
        self.path = Path(path)
        self.unit = unit          # what a record is called in messages ("frames", "rows")
        self.header = bytes(header)
        self.count_offset = count_offset
        self.format_count = format_count
        self.overwrite = overwrite
        self.page_lines = page_lines
        self.records = 0          # complete records on disk under self.path
        self.exists = False       # whether self.path was created by this stream
        self._fd: int | None = None
        self._size = 0            # bytes of the last complete chunk (the file's valid length)
        self._closed = False
        self._check_target()
        from lmm.data.outputs import lock_output
        lock_output(self.path, unit)   # a second process streaming to this path is refused, naming the first

    def _check_target(self) -> None:
        path = self.path
        if path.is_dir():
            raise IsADirectoryError(errno.EISDIR, "is a folder, not a file", str(path))
        if not self.overwrite and os.path.lexists(path):
            raise FileExistsError(errno.EEXIST, "exists already (a recording never overwrites a file)", str(path))
        if len(path.name.encode("utf-8", "surrogateescape")) > 255 - 24:  # room for the temporary name
            raise OSError(errno.ENAMETOOLONG, "file name too long", str(path))
        if not path.parent.is_dir():
            raise FileNotFoundError(errno.ENOENT, "the folder does not exist", str(path))
        probe = self._temp_name("probe")
        try:
            fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except OSError as e:
            raise OSError(e.errno, f"cannot write in its folder ({e.strerror})", str(path)) from None
        os.close(fd)
        os.unlink(probe)

    def _temp_name(self, kind: str) -> Path:
        return self.path.with_name(f".{self.path.name}.{os.getpid()}.{kind}")

    @property
    def closed(self) -> bool:
        return self._closed

    def append(self, data: bytes, n_records: int) -> None:
        """Append ``n_records`` complete records (``data``), update the count, fsync. On failure the
        file is cut back to its last complete chunk and :class:`StreamWriteError` is raised."""
        if self._closed:
            raise ValueError(f"{self.path}: the stream is closed")
        if n_records <= 0:
            return
        try:
            if self._fd is None:
                self._create(data, n_records)
            else:
                self._append(data, n_records)
        except OSError as e:
            self._fail(e)

    def _create(self, data: bytes, n_records: int) -> None:
        tmp = self._temp_name("partial")
        fd = os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            header = self.header
            if self.count_offset is not None:
                field = self.format_count(n_records)
                header = header[:self.count_offset] + field + header[self.count_offset + len(field):]
            if self.page_lines:
                # laid out as every later chunk is: where a line lands depends on the lines before it
                # only, not on how they were split into chunks (the flushes follow the wall clock), so
                # the same records give the same bytes
                data = lines_within_pages(data, len(header))
            _write_all(fd, header + data)
            os.fsync(fd)
            if self.overwrite:
                replace_regular(tmp, self.path)   # never over a device or a FIFO
            else:
                os.link(tmp, self.path)      # fails rather than replace a file made meanwhile
                os.unlink(tmp)
        except BaseException:
            os.close(fd)
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
        self._fd = fd
        self.exists = True
        self._size = len(header) + len(data)
        self.records = n_records
        _fsync_folder(self.path.parent)

    def _append(self, data: bytes, n_records: int) -> None:
        try:
            if self.page_lines:
                data = lines_within_pages(data, self._size)
                _write_by_page(self._fd, data, self._size)
            else:
                _write_all(self._fd, data, self._size)
            count = self.records + n_records
            if self.count_offset is not None:
                os.pwrite(self._fd, self.format_count(count), self.count_offset)
            os.fsync(self._fd)
        except OSError:
            # back to the last complete chunk: the header's count still says self.records
            os.ftruncate(self._fd, self._size)
            if self.count_offset is not None:
                os.pwrite(self._fd, self.format_count(self.records), self.count_offset)
            os.fsync(self._fd)
            raise
        self._size += len(data)
        self.records = count

    def _fail(self, e: OSError) -> None:
        self.close()
        kept = (f"the file keeps its first {self.records} {self.unit}" if self.exists
                else "nothing was written")
        raise StreamWriteError(e.errno, f"{e.strerror or e}; {kept}", str(self.path)) from None

    def close(self) -> None:
        """Close the file (nothing is written here; a stream with no record leaves no file)."""
        if not self._closed:
            from lmm.data.outputs import release_output
            release_output(self.path)
        self._closed = True
        if self._fd is not None:
            try:
                os.close(self._fd)
            finally:
                self._fd = None


class BufferedStreamWriter:
    """Records kept in memory and appended to a :class:`StreamFile` at least every ``flush_interval_s``
    seconds of ``_clock``: what the BVH recorder and the input log writer share. A subclass sets
    ``_stream``, ``_pending`` (a list), ``_clock``, ``_last_flush`` and ``flush_interval_s``, and encodes
    a batch of pending records with :meth:`_encode`."""

    def _encode(self, pending: list) -> bytes:
        raise NotImplementedError

    @property
    def exists(self) -> bool:
        """Whether the file was created (it is, with the first flushed records)."""
        return self._stream.exists

    def _flush_if_due(self) -> None:
        if self._clock() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Append the pending records whole and fsync. Raises :class:`StreamWriteError` (the file keeps
        its earlier records) on a failed write."""
        if self._stream.closed:
            return
        if self._pending:
            pending, self._pending = self._pending, []
            self._stream.append(self._encode(pending), len(pending))
        self._last_flush = self._clock()

    def close(self) -> None:
        """Flush and close; with no record ever written there is no file. Closing twice, or after a
        failed write, does nothing."""
        if self._stream.closed:
            return
        try:
            self.flush()
        finally:
            self._stream.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def lines_within_pages(data: bytes, offset: int, page: int = PAGE) -> bytes:
    """``data`` (whole lines) as written at file ``offset`` with no line crossing a ``page`` boundary: a line
    that would is preceded by spaces up to the boundary (lines longer than a page are left as they are)."""
    out, pos = [], offset
    for line in data.splitlines(keepends=True):
        room = page - pos % page
        if room < len(line) <= page:
            out.append(b" " * room)
            pos += room
        out.append(line)
        pos += len(line)
    return b"".join(out)


def _write_by_page(fd: int, data: bytes, offset: int, page: int = PAGE) -> None:
    """``data`` written at ``offset`` one page of the file at a time (a kill stops a write only between
    pages, so each call is whole or not at all)."""
    view = memoryview(data)
    while view:
        n = page - offset % page
        _write_all(fd, view[:n], offset)
        view, offset = view[n:], offset + n


def _write_all(fd: int, data: bytes, offset: int | None = None) -> None:
    """Write every byte of ``data`` (at ``offset``, else at the current position); a short write is
    continued, so only an error stops it."""
    view = memoryview(data)
    while view:
        n = os.write(fd, view) if offset is None else os.pwrite(fd, view, offset)
        if n <= 0:
            raise OSError(errno.EIO, "the write made no progress")
        view = view[n:]
        if offset is not None:
            offset += n


def _fsync_folder(folder: Path) -> None:
    """Make a rename durable (best effort: some file systems cannot open or fsync a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def repair_count(path, count_offset: int, format_count, header_size: int) -> int:
    """Make a stream's header count match its complete records after a kill between an append and the
    count rewrite (see the module doc): drop a partial last line, count the lines after the header,
    rewrite the count field. Returns the count. Lines must be the records (one per line)."""
    path = Path(path)
    with open(path, "r+b") as f:
        f.seek(header_size)
        body = f.read()
        end = body.rfind(b"\n") + 1
        if end < len(body):
            f.truncate(header_size + end)
        n = sum(1 for line in body[:end].split(b"\n") if line.strip())
        f.seek(count_offset)
        f.write(format_count(n))
        f.flush()
        os.fsync(f.fileno())
    return n
