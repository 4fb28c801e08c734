"""Contact models of the flesh simulation (paper 000 Eq. 3): a small interface (``base``) and its
implementations, triangle penalty contacts (``triangles``: lips and lids on each other, flesh on
bone and teeth) and the eyeball spheres (``eyeballs``: the lids sliding on the eyes).

``Simulator`` holds a ``ContactSet`` of them; Newton and the adjoint ask the interface only.
"""
from __future__ import annotations

import numpy as np

from .base import CONTACT_SMOOTHING, ContactModel, ContactSet, penalty
from .eyeballs import EyeballContacts, eyeball_spheres
from .triangles import MIN_CONTACT_RADIUS, TriangleContacts

__all__ = ["CONTACT_SMOOTHING", "MIN_CONTACT_RADIUS", "ContactModel", "ContactSet", "EyeballContacts",
           "TriangleContacts", "default_contacts", "penalty"]


def default_contacts(model, free_mask, stiffness, radius, adjacency=None):
    """A face's contacts: triangle penalty contacts of the free boundary vertices and the
    eyeball spheres, each with stiffness (N/m) and pairing radius (m); adjacency: the tet
    mesh's vertex connectivity when the caller has it. Returns [TriangleContacts,
    EyeballContacts]."""
    triangles = TriangleContacts(model, free_mask, stiffness, radius, adjacency)
    return [triangles, EyeballContacts(np.asarray(model.rest_positions, float), triangles.candidates,
                                       eyeball_spheres(model), stiffness, radius)]
