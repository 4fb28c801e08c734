from ._env import configure_llvm as _c
_c()
