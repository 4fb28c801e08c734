"""Process environment set-up: Dr.Jit's LLVM (before Dr.Jit is imported) and BLAS threads."""
import glob
import os

_LLVM_CANDIDATES = (
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
    "/usr/lib/aarch64-linux-gnu/libLLVM.so.19.1",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so",
    "/usr/lib/llvm-19/lib/libLLVM.so.1",
    "/usr/lib/llvm-19/lib/libLLVM-19.so",
)


def configure_llvm() -> str | None:
    """Point Dr.Jit's CPU backend at LLVM 19 unless the user chose a library already.

    mitsuba 3.9 / drjit 1.5 abort on Debian's LLVM 15/16 (``Cannot select: f32 =
    fminimum``); LLVM 19 works. Returns the path in use, or None if none was found.
    """
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return os.environ["DRJIT_LIBLLVM_PATH"]
    found = [p for p in _LLVM_CANDIDATES if os.path.exists(p)]
    found += sorted(glob.glob("/usr/lib/*/libLLVM.so.19*"))
    if found:
        os.environ["DRJIT_LIBLLVM_PATH"] = found[0]
        return found[0]
    return None


def limit_openblas_threads() -> bool:
    """Run OpenBLAS (numpy's and scipy's) on one thread unless OPENBLAS_NUM_THREADS is set.

    OpenBLAS's threads busy-wait after each call, and on a machine with few cores they take
    the cores from what runs next: a PARDISO factorisation right after a numpy matrix product
    runs at half speed (bench/RESULTS.md has the measurements). The simulation's own threads are
    numba's and MKL's; numpy's products here are small. Sets the variable for libraries
    loaded later (and for Dask workers) and limits the ones loaded already (threadpoolctl).
    Returns whether it limited anything.
    """
    if "OPENBLAS_NUM_THREADS" in os.environ:
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:     # pragma: no cover - a dependency; the variable still holds for later loads
        return True
    ThreadpoolController().select(internal_api="openblas").limit(limits=1)
    return True


def debugging():
    """Whether the user asked for tracebacks and native libraries' log lines (``--debug`` sets
    INVFACE_DEBUG=1)."""
    return os.environ.get("INVFACE_DEBUG", "") not in ("", "0")


class native_stderr_quiet:
    """Silence what native code writes to the process's stderr (file descriptor 2) inside the
    block, unless ``debugging()``: MediaPipe's and TFLite's C++ log lines ("W0000 ...
    face_landmarker_graph.cc") come from there on every detector run. Python's own
    ``sys.stderr`` is flushed first; exceptions still propagate."""

    def __enter__(self):
        import sys
        self.saved = None
        if debugging():
            return self
        sys.stderr.flush()
        self.saved, self.null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
        os.dup2(self.null, 2)
        return self

    def __exit__(self, *exc):
        import sys
        if self.saved is not None:
            sys.stderr.flush()
            os.dup2(self.saved, 2)
            os.close(self.saved)
            os.close(self.null)
