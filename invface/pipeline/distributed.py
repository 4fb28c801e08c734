"""Frame-parallel sequence fitting on Dask (``dask.distributed``): no scheduler of our own.

    rows = fit_sequence_distributed(model, clip, calibration, out, kinds, workers=2)
    rows = fit_sequence_distributed(..., scheduler="tcp://10.0.0.5:8786")   # a running cluster

The clip is split into contiguous chunks, one per worker (or ``chunks``); each chunk is one
task that fits its frames in order, warm-started inside the chunk, exactly as the single-process
run does (``frames.fit_frames``), and writes each frame's files to ``out`` as it finishes
(so the workers must see ``out``: a local cluster always does, a remote one needs a shared
file system). The model and the calibration are scattered to every worker once. A chunk's
first frame has no predecessor in its task, so a second pass refits the first ``overlap``
frames of every chunk but the first, warm-started from the previous chunk's last frame.
A worker that dies has its chunk re-run (``retries``); the re-run skips the frames it
already wrote (their ``input_hash`` matches). Progress: the frames finished in ``out``,
polled once a second, as one count over all frames.
"""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path

from ..errors import InvfaceError
from .plates import _say, model_kinds
from .frames import fit_frames
from .runs import fit_record, start_from

RETRIES = 2


def chunk_bounds(n, chunks):
    """Contiguous [start, stop) position ranges splitting n frames into ``chunks`` parts
    (sizes differing by at most one; no empty part)."""
    chunks = max(1, min(int(chunks), n))
    edges = [round(i * n / chunks) for i in range(chunks + 1)]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:])]


def _pin_threads(n):
    """Cap this process's compute threads at n (None: leave them): Dr.Jit's LLVM pool and
    Numba's (BLAS is capped by Dask's nanny already). Without it each local worker starts a
    pool as wide as the machine and the workers' pools fight over the cores."""
    if not n:
        return
    import drjit as dr
    import numba
    dr.set_thread_count(n)
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))


def _fit_chunk(model, clip, calibration, out, kinds, start, stop, starts, inputs, skip, record, options,
               threads=None):
    """One task: ``fit_frames`` over positions [start, stop) (runs on a worker with at most
    ``threads`` compute threads)."""
    _pin_threads(threads)
    return fit_frames(model, clip, calibration, out, kinds, start=start, stop=stop, starts=starts, inputs=inputs,
                      skip=skip, record=record, **options)


def _finished_frames(out, names, kinds, inputs):
    """How many of the frames have every kind's fit.json from this run's inputs."""
    return sum(all((fit_record(Path(out) / name, k) or {}).get("run_inputs") == inputs for k in kinds)
               for name in names)


def _client(workers, scheduler):
    from distributed import Client, LocalCluster
    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError) as e:
            raise InvfaceError(f"--scheduler {scheduler}: no Dask scheduler answers there ({e})") from None
    cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR)
    return Client(cluster), cluster


def fit_sequence_distributed(model, clip, calibration, out, kinds=("blendshape",), inputs="", workers=2,
                             scheduler=None, chunks=None, overlap=1, progress=None, **options):
    """Fit a clip's frames on a Dask cluster: a ``distributed.LocalCluster`` of ``workers``
    single-threaded processes, or the running cluster at ``scheduler`` (an address). Options
    as ``frames.fit_frames``. progress receives {"done": frames, "total": frames} as frames
    finish and {"message": ...} for the passes. Returns the per-frame summaries in order."""
    from distributed import wait
    kinds = model_kinds(kinds)
    if out is None:
        raise InvfaceError("a distributed run writes its frames to an output folder: give one")
    client, cluster = _client(workers, scheduler)
    try:
        n = len(client.scheduler_info().get("workers", {})) or int(workers or 1)
        bounds = chunk_bounds(len(clip), chunks or n)
        _say(progress, message=f"{len(clip)} frames in {len(bounds)} chunks on {n} Dask workers "
                               f"({scheduler or 'local cluster'})")
        m, c = client.scatter([model, calibration], broadcast=True)
        threads = None if scheduler else max(1, (os.cpu_count() or 1) // n)    # a local cluster shares this machine
        job = f"invface-{inputs}-{time.time_ns()}"
        futs = [client.submit(_fit_chunk, m, clip, c, out, kinds, a, b, None, inputs, True, {}, options, threads,
                              key=f"{job}-chunk-{a}", retries=RETRIES, pure=False) for a, b in bounds]
        names = clip.names
        while True:
            _say(progress, done=_finished_frames(out, names, kinds, inputs), total=len(clip))
            if all(f.done() for f in futs):
                break
            try:
                wait(futs, timeout=1.0)
            except TimeoutError:
                pass
        rows = [r for part in _gather(client, futs, bounds) for r in part]
        # second pass: each chunk's first frames from the previous chunk's last frame
        second = []
        for (a, b), (_, pb) in zip(bounds[1:], bounds[:-1]):
            starts = {}
            for k in kinds:
                rec = fit_record(Path(out) / names[pb - 1], k)
                if rec is not None and not rec.get("flagged"):
                    starts[k] = start_from(model, rec)
            if starts:
                second.append(client.submit(_fit_chunk, m, clip, c, out, kinds, a, min(a + overlap, b), starts,
                                            inputs, False, {"second_pass": True}, options, threads,
                                            key=f"{job}-boundary-{a}", retries=RETRIES, pure=False))
        if second:
            _say(progress, message=f"second pass: {len(second)} chunk boundaries, {overlap} frame(s) each, "
                                   "warm-started from the chunk before")
            redo = {r["name"]: r for part in _gather(client, second, bounds[1:]) for r in part}
            rows = [redo.get(r["name"], r) for r in rows]
        _say(progress, done=_finished_frames(out, names, kinds, inputs), total=len(clip))
        return rows
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _gather(client, futs, bounds):
    """The chunks' results; a chunk that failed (after its retries) is an InvfaceError naming
    its frames and the reason."""
    out = []
    for f, (a, b) in zip(futs, bounds):
        try:
            out.append(f.result())
        except InvfaceError as e:
            raise InvfaceError(f"frames {a}-{b - 1}: {e}") from None
        except Exception as e:                   # a worker lost more than RETRIES times, ...
            raise InvfaceError(f"frames {a}-{b - 1}: the Dask task failed: {type(e).__name__}: {e}") from None
    return out
