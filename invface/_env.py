"""Process environment set-up that must happen before Dr.Jit is imported."""
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
