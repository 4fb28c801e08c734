"""Errors that invface raises for bad input or failed computations.

Every message names the input (file, field, option) and says how to fix it. The CLI
prints an ``InvfaceError`` as one line and exits non-zero, without a traceback.
"""


class InvfaceError(Exception):
    """Base class of every error invface raises on purpose."""


class BundleError(InvfaceError):
    """A FaceModel bundle (.npz) is missing, truncated, corrupted or inconsistent."""


class MeshError(InvfaceError):
    """A mesh is unusable: inverted or degenerate elements, non-manifold, bad indices."""


class ControlsError(InvfaceError):
    """Animator controls are malformed: unknown names, wrong shapes, non-finite values."""


class ConfigError(InvfaceError):
    """An option or parameter value is out of range."""


class DependencyError(InvfaceError):
    """A required system component (LLVM for Dr.Jit, a solver) cannot be found."""


class ImageError(InvfaceError):
    """An image or plate is unreadable, truncated, non-finite or the wrong size."""


class CameraError(InvfaceError):
    """A camera file is missing fields, malformed, or disagrees with its plate."""


class SimulationError(InvfaceError):
    """A simulation could not reach or use an equilibrium (Newton did not converge, an
    inverted tet, a state that is not a stable equilibrium). Optimisers treat it as a
    rejected trial point."""
