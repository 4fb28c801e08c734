"""The analytic shape of the built-in head: skin and bone as implicit surfaces.

Frame (DESIGN.md): metres, +Y up, the face looks along +Z, +X is the actor's left. The
origin lies near the ear canals. Proportions follow adult anthropometry (inter-ocular
distance ~37 mm, mouth width ~50 mm, nose length ~50 mm); soft-tissue depths follow a
forensic table (DEPTH_SITES). Everything is symmetric in x by construction (|x| is used).

Both fields are evaluated on points ``p`` (..., 3) and return approximate signed distances.
"""
import numpy as np

from .sdf import ellipsoid, round_cone, smax, smin

# Key anatomical positions (metres), right/left symmetric: given for the left side (x > 0).
EYE_CENTER = np.array([0.031, 0.034, 0.079])     # eyeball centre
EYE_RADIUS = 0.0122
# The canthi lie below the pupil's centre: the eye corners' line 2.3 mm under it, measured as
# the detector measures photos (bench/eye_rest.py); the lateral canthus 1.5 mm above the medial.
EYE_INNER = np.array([0.0185, 0.0310, 0.0930])   # endocanthion (on the skin, approx.)
EYE_OUTER = np.array([0.0445, 0.0325, 0.0870])   # exocanthion
MOUTH_Y = -0.0345                                # stomion height
MOUTH_CORNER = np.array([0.0250, -0.0355, 0.1010])
JAW_PIVOT = np.array([0.0, 0.006, -0.004])       # midpoint between the condyles
CONDYLE_X = 0.050
RHINION_Y = 0.020                                # lower end of the nasal bones
OCCLUSAL_TILT = np.tan(np.radians(10))           # the occlusal plane's rise towards the back


def skin_field(p):
    """Signed distance-like field of the skin (negative inside the head). p: (..., 3) m."""
    return head_field(p)


def head_field(p, soft=True):
    """The skin's field (soft=True), or with soft=False the head without what no bone lies
    under: the neck, the cartilaginous nose below the rhinion, the eyeballs under the lids and
    the lips' vermilion rolls (the face whose inward offset is the skull, template.skull).
    p: (..., 3) m."""
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
    if soft:    # neck
        f = smin(f, round_cone(q, (0.0, -0.05, -0.012), (0.0, -0.26, -0.02), 0.055, 0.058), 0.03)
    # brow ridges
    f = smin(f, round_cone(q, (0.010, 0.057, 0.097), (0.050, 0.056, 0.083), 0.007, 0.006), 0.012)
    # orbits: carve the socket, then add the eyeball under closed lids
    f = smax(f, -ellipsoid(q, (0.032, 0.035, 0.099), (0.020, 0.014, 0.016)), 0.008)
    if soft:
        f = smin(f, ellipsoid(q, EYE_CENTER + (0.0, 0.0, 0.0015), (0.0140, 0.0115, 0.0125)), 0.005)
    # nasion dip between the brows and the nasal dorsum
    f = smax(f, -ellipsoid(q, (0.0, 0.0385, 0.1075), (0.010, 0.007, 0.0045)), 0.004)
    # nose: dorsum from nasion to tip (its bony part ends at the rhinion), tip lobule, alae
    dorsum = round_cone(q, (0.0, 0.034, 0.098), (0.0, 0.008, 0.121), 0.0055, 0.0095)
    if not soft:
        f = smin(f, np.maximum(dorsum, RHINION_Y - 0.007 - q[..., 1]), 0.006)   # cut by the aperture
    else:
        f = smin(f, dorsum, 0.006)
        f = smin(f, ellipsoid(q, (0.0, 0.004, 0.121), (0.011, 0.010, 0.010)), 0.006)
        f = smin(f, ellipsoid(q, (0.0135, -0.002, 0.108), (0.0085, 0.0075, 0.0085)), 0.005)
        # columella / subnasal transition
        f = smin(f, ellipsoid(q, (0.0, -0.006, 0.115), (0.004, 0.006, 0.008)), 0.006)
        # nostrils: shallow dents under the alae
        f = smax(f, -ellipsoid(q, (0.0075, -0.0080, 0.1155), (0.0045, 0.0016, 0.0050)), 0.002)
    # philtrum and lips
    f = smin(f, ellipsoid(q, (0.0, -0.020, 0.103), (0.020, 0.012, 0.011)), 0.008)
    if soft:    # the lips' vermilion rolls (no bone follows them)
        f = smin(f, ellipsoid(q, (0.0, -0.0285, 0.1080), (0.0250, 0.0078, 0.0098)), 0.003)
        f = smin(f, ellipsoid(q, (0.0, -0.0410, 0.1050), (0.0240, 0.0082, 0.0102)), 0.003)
    # mentolabial sulcus
    f = smax(f, -ellipsoid(q, (0.0, -0.0525, 0.1125), (0.016, 0.004, 0.004)), 0.004)
    return f


# Soft-tissue depths (metres) at craniometric sites, the mean depths of normal-build adult
# White males in Rhine & Moore's table (J.S. Rhine, C.E. Moore, "Tables of facial tissue
# thickness of American Caucasoids in forensic anthropology", Maxwell Museum Technical Series
# 1, 1984; reproduced in K.T. Taylor, Forensic Art and Illustration, CRC 2001, table 12.1).
# Each site is the skin point on the ray from grid.CENTER through its approximate position.
# name: (x, y, z approx., depth m, table site?)
DEPTH_SITES = {
    "supraglabella": (0.000, 0.075, 0.100, 0.00425, True),
    "glabella": (0.000, 0.058, 0.105, 0.00525, True),
    "nasion": (0.000, 0.0385, 0.102, 0.00650, True),
    "rhinion": (0.000, 0.020, 0.115, 0.00310, True),          # end of the nasal bones
    "mid_philtrum": (0.000, -0.018, 0.110, 0.01000, True),
    "labrale_superius": (0.000, -0.026, 0.118, 0.00975, True),   # upper lip margin
    "labrale_inferius": (0.000, -0.045, 0.115, 0.01100, True),   # lower lip margin
    "chin_lip_fold": (0.000, -0.0525, 0.112, 0.01075, True),
    "mental_eminence": (0.000, -0.066, 0.105, 0.01125, True),    # chin (pogonion)
    "beneath_chin": (0.000, -0.082, 0.090, 0.00725, True),
    "frontal_eminence": (0.030, 0.085, 0.095, 0.00425, True),
    "supraorbital": (0.032, 0.056, 0.095, 0.00825, True),
    "suborbital": (0.032, 0.014, 0.095, 0.00575, True),
    "inferior_malar": (0.040, -0.005, 0.085, 0.01325, True),
    "lateral_orbit": (0.050, 0.033, 0.075, 0.01000, True),
    "zygion": (0.066, 0.012, 0.030, 0.00725, True),             # the zygomatic arch
    "supraglenoid": (0.066, 0.020, 0.000, 0.00850, True),
    "gonion": (0.052, -0.065, 0.010, 0.01150, True),
    "supra_m2": (0.045, -0.015, 0.060, 0.02225, True),
    "mid_masseter": (0.050, -0.034, 0.050, 0.01900, True),      # the table's occlusal line
    "sub_m2": (0.045, -0.055, 0.060, 0.01500, True),
    # not in the table: the mouth corner, between the lips' 10-11 mm and the occlusal line's
    # 19 mm (without it the blend falls to the 6 mm default there); the nose's cartilage and
    # the subnasal soft tissue count as flesh
    "cheilion": (0.027, -0.035, 0.100, 0.01300, False),
    "pronasale": (0.000, 0.004, 0.131, 0.02800, False),
    "subnasale": (0.000, -0.010, 0.116, 0.01400, False),
}
CARTILAGE_SITES = ("pronasale", "subnasale")
_SIGMA = 0.011       # m, the reach of each site
_BASE_DEPTH = 0.0060


def depth_site_points():
    """name -> skin point (3,) m of every depth site (rays from grid.CENTER, cached)."""
    global _SITE_POINTS
    if _SITE_POINTS is None:
        from . import grid
        names = list(DEPTH_SITES)
        tgt = np.array([DEPTH_SITES[n][:3] for n in names]) - grid.CENTER
        a, b = grid.angles(tgt / np.linalg.norm(tgt, axis=1, keepdims=True))
        pts = grid.CENTER + grid.raycast(skin_field, a, b)[:, None] * grid.directions(a, b)
        _SITE_POINTS = dict(zip(names, pts))
    return _SITE_POINTS


_SITE_POINTS = None


def tissue_depth(p, cartilage=True):
    """Soft-tissue thickness (m) at skin points p (..., 3): the sites' depths blended by
    normalised Gaussian weights (reach 11 mm), fading to 6 mm far from every site.
    cartilage=False leaves out the nose's cartilage sites (the skull's depth under the nose)."""
    pts = depth_site_points()
    names = [n for n in DEPTH_SITES if cartilage or n not in CARTILAGE_SITES]
    sites = np.array([pts[n] for n in names])
    depth = np.array([DEPTH_SITES[n][3] for n in names])
    q = np.concatenate([np.abs(p[..., :1]), p[..., 1:]], axis=-1)[..., None, :]
    d2 = np.sum((q - sites) ** 2, axis=-1)
    w = np.exp(-d2 / (2 * _SIGMA ** 2))
    wsum = w.sum(-1)
    val = (w * depth).sum(-1) / np.maximum(wsum, 1e-12)
    blend = np.clip(wsum, 0, 1)
    return blend * val + (1 - blend) * _BASE_DEPTH
