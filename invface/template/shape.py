"""The analytic shape of the built-in head: skin and bone as implicit surfaces.

Frame (DESIGN.md): metres, +Y up, the face looks along +Z, +X is the actor's left. The
origin lies near the ear canals. Proportions follow adult anthropometry (inter-ocular
distance ~37 mm, mouth width ~50 mm, nose length ~50 mm, soft-tissue depths from forensic
tables: ~5 mm on the forehead, ~3 mm on the nasal dorsum, 10-13 mm at the lips and chin,
15-20 mm in the mid cheek). Everything is symmetric in x by construction (|x| is used).

Both fields are evaluated on points ``p`` (..., 3) and return approximate signed distances.
"""
import numpy as np

from .sdf import ellipsoid, round_cone, smax, smin

# Key anatomical positions (metres), right/left symmetric: given for the left side (x > 0).
EYE_CENTER = np.array([0.031, 0.034, 0.079])     # eyeball centre
EYE_RADIUS = 0.0122
EYE_INNER = np.array([0.0185, 0.0330, 0.0930])   # endocanthion (on the skin, approx.)
EYE_OUTER = np.array([0.0445, 0.0345, 0.0870])   # exocanthion
MOUTH_Y = -0.0345                                # stomion height
MOUTH_CORNER = np.array([0.0250, -0.0355, 0.1010])
JAW_PIVOT = np.array([0.0, 0.006, -0.004])       # midpoint between the condyles
CONDYLE_X = 0.050


def skin_field(p):
    """Signed distance-like field of the skin (negative inside the head). p: (..., 3) m."""
    q = p.copy()
    q[..., 0] = np.abs(q[..., 0])
    # Cranium, forehead and face masses.
    f = ellipsoid(q, (0.0, 0.045, -0.006), (0.075, 0.101, 0.098))
    f = smin(f, ellipsoid(q, (0.0, 0.058, 0.022), (0.066, 0.072, 0.084)), 0.02)
    # midface / maxilla and cheeks
    f = smin(f, ellipsoid(q, (0.0, 0.006, 0.026), (0.063, 0.056, 0.084)), 0.02)
    # cheekbones (zygoma)
    f = smin(f, ellipsoid(q, (0.049, 0.016, 0.066), (0.022, 0.015, 0.024)), 0.015)
    # lower face: a mass that tapers to the chin, and the mandible body
    f = smin(f, ellipsoid(q, (0.0, -0.036, 0.050), (0.050, 0.045, 0.062)), 0.02)
    f = smin(f, round_cone(q, (0.018, -0.064, 0.086), (0.043, -0.058, 0.030), 0.014, 0.012), 0.02)
    f = smin(f, ellipsoid(q, (0.0, -0.066, 0.088), (0.024, 0.016, 0.018)), 0.012)
    # ramus / mastoid filler behind the jaw angle (keeps the surface star-shaped)
    f = smin(f, ellipsoid(q, (0.050, -0.015, 0.0), (0.020, 0.040, 0.032)), 0.02)
    # neck
    f = smin(f, round_cone(q, (0.0, -0.05, -0.012), (0.0, -0.26, -0.02), 0.055, 0.058), 0.03)
    # brow ridges
    f = smin(f, round_cone(q, (0.010, 0.057, 0.097), (0.050, 0.056, 0.083), 0.007, 0.006), 0.012)
    # orbits: carve the socket, then add the eyeball under closed lids
    f = smax(f, -ellipsoid(q, (0.032, 0.035, 0.099), (0.020, 0.014, 0.016)), 0.008)
    f = smin(f, ellipsoid(q, EYE_CENTER + (0.0, 0.0, 0.0015), (0.0140, 0.0115, 0.0125)), 0.005)
    # nasion dip between the brows and the nasal dorsum
    f = smax(f, -ellipsoid(q, (0.0, 0.0385, 0.1075), (0.010, 0.007, 0.0045)), 0.004)
    # nose: dorsum from nasion to tip, tip lobule, alae
    f = smin(f, round_cone(q, (0.0, 0.034, 0.098), (0.0, 0.008, 0.121), 0.0055, 0.0095), 0.006)
    f = smin(f, ellipsoid(q, (0.0, 0.004, 0.121), (0.011, 0.010, 0.010)), 0.006)
    f = smin(f, ellipsoid(q, (0.0135, -0.002, 0.108), (0.0085, 0.0075, 0.0085)), 0.005)
    # columella / subnasal transition
    f = smin(f, ellipsoid(q, (0.0, -0.006, 0.115), (0.004, 0.006, 0.008)), 0.006)
    # nostrils: shallow dents under the alae
    f = smax(f, -ellipsoid(q, (0.0075, -0.0080, 0.1155), (0.0045, 0.0016, 0.0050)), 0.002)
    # philtrum and lips
    f = smin(f, ellipsoid(q, (0.0, -0.020, 0.103), (0.020, 0.012, 0.011)), 0.008)
    f = smin(f, ellipsoid(q, (0.0, -0.0285, 0.1080), (0.0250, 0.0078, 0.0098)), 0.003)
    f = smin(f, ellipsoid(q, (0.0, -0.0410, 0.1050), (0.0240, 0.0082, 0.0102)), 0.003)
    # mentolabial sulcus
    f = smax(f, -ellipsoid(q, (0.0, -0.0525, 0.1125), (0.016, 0.004, 0.004)), 0.004)
    return f


# Soft-tissue depth (metres) at anatomical sites; interpolated smoothly over the face.
_DEPTH_SITES = np.array([
    # x, y, z (on skin, approx.), depth
    [0.000, 0.090, 0.100, 0.0050],   # mid forehead
    [0.000, 0.060, 0.105, 0.0055],   # glabella
    [0.000, 0.038, 0.102, 0.0065],   # nasion
    [0.000, 0.020, 0.112, 0.0030],   # rhinion (nasal bone end)
    [0.000, 0.004, 0.131, 0.0280],   # nose tip (cartilage counts as flesh)
    [0.000, -0.012, 0.116, 0.0140],  # subnasale
    [0.000, -0.028, 0.118, 0.0120],  # upper lip
    [0.000, -0.042, 0.115, 0.0130],  # lower lip
    [0.000, -0.060, 0.110, 0.0110],  # mentolabial / chin
    [0.000, -0.076, 0.104, 0.0100],  # menton
    [0.030, 0.058, 0.095, 0.0060],   # supraorbital
    [0.045, 0.012, 0.080, 0.0090],   # zygomatic
    [0.040, -0.010, 0.085, 0.0200],  # mid cheek (buccal)
    [0.055, -0.040, 0.055, 0.0160],  # near gonion / masseter
    [0.060, 0.040, 0.050, 0.0055],   # temple
], float)


def tissue_depth(p):
    """Soft-tissue thickness (m) at skin points p (..., 3), smooth Gaussian interpolation."""
    q = np.concatenate([np.abs(p[..., :1]), p[..., 1:]], axis=-1)[..., None, :]
    sites = _DEPTH_SITES[:, :3]
    d2 = np.sum((q - sites) ** 2, axis=-1)
    w = np.exp(-d2 / (2 * 0.018 ** 2)) + 1e-9
    base = 0.0060
    wsum = w.sum(-1)
    val = (w * _DEPTH_SITES[:, 3]).sum(-1) / wsum
    blend = np.clip(wsum, 0, 1)
    return blend * val + (1 - blend) * base
