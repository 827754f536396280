"""Shards in spawned worker processes, one pipe each, so a dead worker names its shard."""

from __future__ import annotations

import collections
import multiprocessing
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from pathlib import Path

from zoo.data.shard_generator import AgentBuilder, GenerationConfig, ProgressFn, ShardGenerator


class WorkerError(RuntimeError):
    """A worker process raised or died while playing a shard (the message names the shard)."""


def _work(
    config: GenerationConfig, num_envs: int, build_agent: AgentBuilder, out: str, conn: Connection
) -> None:
    """A worker process: plays each shard index it receives, sending progress, then the
    manifest entry or the traceback of what failed. Stops once the parent is gone (its end of
    the pipe closed)."""
    generator = None
    while True:
        try:
            index = conn.recv()
        except EOFError:
            return
        try:
            if generator is None:  # built here, so a failing build is reported with its shard
                generator = ShardGenerator(config, num_envs, build_agent)
            entry = generator.run(index, Path(out), lambda e, f: conn.send(("progress", (e, f))))
        except BaseException:
            conn.send(("error", traceback.format_exc()))
            return
        conn.send(("done", entry))


def run_pool(
    config: GenerationConfig,
    out: Path,
    todo: list[int],
    workers: int,
    num_envs: int,
    build_agent: AgentBuilder,
    advance: ProgressFn,
    record: Callable[[dict], None],
) -> None:
    """Shards in ``workers`` spawned processes (JAX is not fork-safe), one shard at a time each.

    Every worker has a pipe of its own, so the parent knows which shard each one plays: a
    worker that raises or dies (killed, out of memory) ends the run with a WorkerError naming
    that shard, where a multiprocessing.Pool would wait forever for a killed worker's result.
    Shards finished before are already in the manifest; the other workers are stopped.
    """
    ctx = multiprocessing.get_context("spawn")
    queued = collections.deque(todo)
    busy: dict[Connection, tuple[int, BaseProcess]] = {}
    conns: list[Connection] = []
    procs: list[BaseProcess] = []

    def assign(conn: Connection, proc: BaseProcess) -> None:
        busy[conn] = (queued.popleft(), proc)
        conn.send(busy[conn][0])

    try:
        for _ in range(min(workers, len(queued))):
            conn, child_end = ctx.Pipe()
            proc = ctx.Process(
                target=_work, args=(config, num_envs, build_agent, str(out), child_end), daemon=True
            )
            proc.start()
            child_end.close()  # the worker holds the only other end: its death reads as EOF
            conns.append(conn)
            procs.append(proc)
            assign(conn, proc)
        while busy:
            failures = []
            for conn in wait(list(busy)):
                index, proc = busy[conn]
                try:
                    kind, payload = conn.recv()
                except EOFError:
                    proc.join(timeout=10)
                    del busy[conn]
                    failures.append(
                        f"shard {index}: worker process {proc.pid} died (exit code {proc.exitcode})"
                    )
                    continue
                if kind == "progress":
                    advance(*payload)
                elif kind == "error":
                    del busy[conn]
                    failures.append(f"shard {index}: worker process {proc.pid} failed:\n{payload}")
                else:  # "done"
                    record(payload)
                    if queued and not failures:
                        assign(conn, proc)
                    else:
                        del busy[conn]
            if failures:
                failures.append("finished shards are kept in the manifest")
                raise WorkerError("\n".join(failures))
    finally:
        # idle, or mid-shard after a failure or an interrupt (a rerun redoes that shard);
        # terminating is also quicker than letting each interpreter shut down
        for proc in procs:
            proc.terminate()
            proc.join()
        for conn in conns:
            conn.close()
