"""Frame-parallel sequence fitting on Dask (``dask.distributed``): no scheduler of our own.

    rows = fit_sequence_distributed(model, clip, calibration, out, kinds, workers=2)
    rows = fit_sequence_distributed(..., scheduler="tls://10.0.0.5:8786",   # a running cluster
                                    security=scheduler_security("tls://10.0.0.5:8786", ca, cert, key))

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


CONNECT_TIMEOUT = "20s"       # how long a Client waits for a scheduler to answer


def _loopback(host):
    """Whether a host name or address is this machine's loopback."""
    import ipaddress
    if host in ("localhost", ""):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def scheduler_security(address, tls_ca=None, tls_cert=None, tls_key=None, insecure=False):
    """Check a Dask scheduler address before anything connects to it, and return the
    ``distributed.Security`` to connect with (None for plain TCP).

    The model, the calibration and the results travel pickled, so whoever can reach the
    scheduler, or join it as a worker, can run code in this process. Hence:
    - ``tls://HOST:PORT`` connects with TLS and mutual authentication: the CA that signed the
      cluster's certificates and this client's certificate and key (files), or, without them,
      those of Dask's own configuration (``distributed.comm.tls``);
    - ``tcp://HOST:PORT`` (or ``HOST:PORT``) only on loopback, unless ``insecure`` (a network
      the user trusts, said explicitly).
    Raises InvfaceError naming the option and the fix; connects to nothing."""
    from urllib.parse import urlsplit
    scheme, _, rest = address.rpartition("://")
    scheme = scheme or "tcp"
    host = urlsplit(f"//{rest}").hostname or ""
    if scheme == "tls":
        files = {"--tls-ca": tls_ca, "--tls-cert": tls_cert, "--tls-key": tls_key}
        given = {k: v for k, v in files.items() if v}
        for opt, f in given.items():
            if not Path(f).is_file():
                raise InvfaceError(f"{opt} {f}: no such file")
        from distributed import Security
        if given:
            if len(given) < 3:
                missing = ", ".join(k for k in files if k not in given)
                raise InvfaceError(f"--scheduler {address}: TLS needs --tls-ca, --tls-cert and --tls-key together "
                                   f"(missing {missing})")
            return Security(tls_ca_file=str(tls_ca), tls_client_cert=str(tls_cert), tls_client_key=str(tls_key),
                            require_encryption=True)
        sec = Security()                                  # Dask's configuration, if it has certificates
        if not sec.tls_ca_file or not sec.tls_client_cert:
            raise InvfaceError(f"--scheduler {address}: a TLS scheduler needs certificates: pass --tls-ca, "
                               "--tls-cert and --tls-key, or set them in Dask's config (distributed.comm.tls)")
        return sec
    if scheme != "tcp":
        raise InvfaceError(f"--scheduler {address}: use tls://HOST:PORT (or tcp:// on this machine), not {scheme}://")
    if not _loopback(host) and not insecure:
        raise InvfaceError(f"--scheduler {address}: plain TCP to another machine is refused: the model and the "
                           "results travel pickled, so anyone who can reach that scheduler or join it as a worker "
                           "can run code here. Use tls://HOST:PORT with --tls-ca, --tls-cert and --tls-key, or pass "
                           "--insecure on a network you trust")
    return None


def _client(workers, scheduler, security=None):
    """(Client, the LocalCluster it owns or None). A local cluster's scheduler, nannies and
    workers listen on 127.0.0.1 only, with no dashboards."""
    from distributed import Client, LocalCluster
    if scheduler:
        try:
            return Client(scheduler, timeout=CONNECT_TIMEOUT, security=security), None
        except (OSError, TimeoutError) as e:
            raise InvfaceError(f"--scheduler {scheduler}: no Dask scheduler answers there ({e})") from None
    cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None, worker_dashboard_address=None, silence_logs=logging.ERROR)
    return Client(cluster), cluster


def fit_sequence_distributed(model, clip, calibration, out, kinds=("blendshape",), inputs="", workers=2,
                             scheduler=None, chunks=None, overlap=1, progress=None, security=None, **options):
    """Fit a clip's frames on a Dask cluster: a ``distributed.LocalCluster`` of ``workers``
    single-threaded processes on loopback, or the running cluster at ``scheduler`` (an address,
    checked by ``scheduler_security`` unless ``security``, a ``distributed.Security``, is given).
    Options as ``frames.fit_frames``. progress receives {"done": frames, "total": frames} as
    frames finish and {"message": ...} for the passes. Returns the per-frame summaries in order."""
    from distributed import wait
    kinds = model_kinds(kinds)
    if out is None:
        raise InvfaceError("a distributed run writes its frames to an output folder: give one")
    if scheduler and security is None:
        security = scheduler_security(scheduler)
    client, cluster = _client(workers, scheduler, security)
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
