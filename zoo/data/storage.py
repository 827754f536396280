"""Where a dataset folder lives: a local path or a folder URL (``https://``, ``s3://``, ...).

A root with a ``scheme://`` is a folder URL: its files (manifest.json, shards) are named by
joining with "/" and read through fsspec, so any protocol fsspec knows works once its package is
installed (``s3://`` needs s3fs, ``gs://`` gcsfs), and no external program is needed
(webdataset's own opener pipes ``http(s)://`` through ``curl`` and ``s3://`` through the aws
CLI). Shards are read front to back as tar streams, so an HTTP shard is one streamed GET and
the server need not support range requests. Local paths are opened with ``open`` as before.

A root ``pipe:COMMAND`` is WebDataset's escape hatch for any other transfer tool: ``{name}`` in
the command is replaced by the file's name and the command's stdout is the file, e.g.
``pipe:aws s3 cp s3://bucket/crafterplay/{name} -`` or ``pipe:ssh host cat /data/cp/{name}``.
A command that reaches the end of its output with a non-zero exit status is an OSError naming
it, the status and its stderr.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import signal
import subprocess
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

import fsspec

STREAMED = ("http", "https")
"""Protocols opened as one stream (``block_size=0``) instead of block-wise range requests."""


PIPE = "pipe:"
NAME = "{name}"
TAIL_BYTES = 1 << 16
"""Output a closed pipe still reads to find its end (tar padding is at most 10 KiB): ending
within it counts as read to the end, so the exit status is checked."""


def is_pipe(root: str | Path) -> bool:
    return str(root).startswith(PIPE)


def is_url(root: str | Path) -> bool:
    return is_pipe(root) or "://" in str(root)


def join(root: str | Path, name: str) -> str:
    """The path or URL of the file ``name`` in the folder ``root``."""
    if is_pipe(root):
        if NAME not in str(root):
            raise ValueError(
                f"{root}: a pipe: dataset root needs {NAME} where the file name goes, e.g. "
                "pipe:aws s3 cp s3://bucket/crafterplay/{name} -"
            )
        return str(root).replace(NAME, name)
    if is_url(root):
        return f"{str(root).rstrip('/')}/{name}"
    return str(Path(root) / name)


def _protocols(url: str) -> list[str]:
    """Every protocol of a (possibly chained) URL: ``simplecache::s3://b/x`` -> simplecache, s3."""
    return [part.split("://", 1)[0] for part in url.split("::")]


def _check_protocols(url: str) -> None:
    """Name the missing package (or the unknown protocol) instead of fsspec's bare error."""
    for protocol in _protocols(url):
        try:
            fsspec.get_filesystem_class(protocol)
        except ImportError as err:
            raise ImportError(f"{url}: {protocol}:// is not readable here: {err}") from None
        except ValueError:
            raise ValueError(
                f"{url}: unknown protocol {protocol!r}; a dataset root is a local folder or a "
                "folder URL fsspec can read (http(s)://, s3:// with s3fs, gs:// with gcsfs)"
            ) from None


def open_binary(url: str | Path) -> IO[bytes]:
    """A local file or URL opened for reading bytes; a missing one raises FileNotFoundError, an
    unreachable one OSError (fsspec's HTTP reports both as FileNotFoundError, the second caused
    by a connection error; only the first means "no such data")."""
    if not is_url(url):
        return open(url, "rb")
    url = str(url)
    if is_pipe(url):
        return _PipeReader(url)
    _check_protocols(url)
    options = {"block_size": 0} if url.split("://", 1)[0] in STREAMED else {}
    try:
        return fsspec.open(url, "rb", **options).open()
    except FileNotFoundError as err:
        if isinstance(err.__cause__, OSError):
            raise OSError(f"{url}: cannot be read ({err.__cause__})") from err.__cause__
        raise FileNotFoundError(f"{url} not found") from None


class _PipeReader:
    """The stdout of a ``pipe:`` command as a binary file. Closing it at (or within
    ``TAIL_BYTES`` of) the end of the output checks the exit status, so a transfer that failed
    is an error, not a short shard; closing it earlier (an epoch that ended mid-shard) stops
    the command."""

    def __init__(self, url: str) -> None:
        self.url = url
        self._ended = False
        self._stderr = tempfile.TemporaryFile()  # a pipe could fill up and stall the command
        self._process = subprocess.Popen(
            url[len(PIPE):], shell=True, stdout=subprocess.PIPE, stderr=self._stderr,
            start_new_session=True,  # its own process group: stopping it stops its children
        )

    def read(self, size: int = -1) -> bytes:
        data = self._process.stdout.read(size)
        self._ended = self._ended or not data or size < 0
        return data

    def close(self) -> None:
        if self._process.returncode is not None:
            return
        if not self._ended:  # a tar reader stops at the end-of-archive marker: drain padding
            self._ended = len(self._process.stdout.read(TAIL_BYTES)) < TAIL_BYTES
        if not self._ended:  # stopped early for real (an epoch ended mid-shard)
            with contextlib.suppress(ProcessLookupError):  # it may be gone already
                os.killpg(self._process.pid, signal.SIGKILL)
        self._process.stdout.close()
        status = self._process.wait()
        self._stderr.seek(0)
        stderr = self._stderr.read().decode(errors="replace").strip()
        self._stderr.close()
        if self._ended and status != 0:
            last = stderr.splitlines()[-1] if stderr else "no stderr"
            raise OSError(f"{self.url}: the command exited with status {status} ({last})")

    def __enter__(self) -> _PipeReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_bytes(url: str | Path) -> bytes:
    with open_binary(url) as f:
        return f.read()


def sha256_of(url: str | Path) -> str:
    return hashlib.sha256(read_bytes(url)).hexdigest()


def tar_samples(shards: Iterable[dict]) -> Iterator[dict]:
    """{"url"} per shard -> webdataset samples: ``wds.tarfile_to_samples`` opening with
    ``open_binary``, so URL shards need no ``curl``. A pipeline stage."""
    # here, not at the top: webdataset loads torch, and manifest readers need neither
    from webdataset.tariterators import group_by_keys, tar_file_expander

    for shard in shards:
        url = shard["url"]
        with open_binary(url) as stream:
            yield from group_by_keys(tar_file_expander([{"url": url, "stream": stream}]))
