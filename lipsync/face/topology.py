"""Named point groups of MediaPipe's 468-point face mesh.

The mesh's vertex numbering is fixed by its canonical face model (MediaPipe's
``canonical_face_model.obj``; the same indices as its ``face_mesh_connections``). The tables
here name the groups lipsync uses, each with why it is used. "Image left" is the side with
the smaller x in a non-mirrored picture, i.e. the subject's right: mesh point 33 is the
outer corner of the subject's right eye.

Contours run from the image-left or image-right end towards the face's midline, so that a
mirror pair (``_l`` / ``_r``) corresponds point for point under reflection, as
``symmetry: true`` banks need.

Examples
--------
>>> LIP_OUTER_UPPER[0], LIP_OUTER_UPPER[-1]
(61, 291)
>>> len(MESH_POINTS)
468
"""

from __future__ import annotations

#: Vertices of the mesh.
MESH_POINTS = range(468)

# Lip contours, corner to corner (image left to image right). The mesh has 40 lip points:
# 20 on the outer, 20 on the inner contour (both corners shared by upper and lower).
LIP_OUTER_UPPER = (61, 185, 40, 39, 37, 0, 267, 269, 270, 409, 291)
LIP_OUTER_LOWER = (61, 146, 91, 181, 84, 17, 314, 405, 321, 375, 291)
LIP_INNER_UPPER = (78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308)
LIP_INNER_LOWER = (78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308)
#: The lip contours' points on the midline (upper outer, lower outer, upper inner, lower inner).
LIP_MIDLINE = (0, 17, 13, 14)
#: Outer and inner mouth corners, image left then image right.
MOUTH_CORNERS = ((61, 78), (291, 308))

#: Pairs of inner-lip points facing each other across the mouth opening, image left to
#: right: their mean distance is the opening (one pair is noisy at the corners' ends).
INNER_LIP_PAIRS = ((81, 178), (82, 87), (13, 14), (312, 317), (311, 402))

# Eyes: outer corner → inner corner along the upper and the lower lid.
EYE_UPPER_L = (33, 246, 161, 160, 159, 158, 157, 173, 133)
EYE_LOWER_L = (33, 7, 163, 144, 145, 153, 154, 155, 133)
EYE_UPPER_R = (263, 466, 388, 387, 386, 385, 384, 398, 362)
EYE_LOWER_R = (263, 249, 390, 373, 374, 380, 381, 382, 362)
#: Lid pairs facing each other (upper, lower), for how open an eye is (blinks).
EYE_LID_PAIRS_L = ((160, 144), (159, 145), (158, 153))
EYE_LID_PAIRS_R = ((387, 373), (386, 374), (385, 380))
#: Eye corners (outer, inner) of each eye.
EYE_CORNERS_L = (33, 133)
EYE_CORNERS_R = (263, 362)

# Brows, outer end → inner end, along their upper edge.
BROW_L = (70, 63, 105, 66, 107)
BROW_R = (300, 293, 334, 296, 336)

# The face oval: the jaw from the ear's level down to the chin, the upper outline from the
# ear's level over the forehead to the midline.
JAW_L = (234, 93, 132, 58, 172, 136, 150, 149, 176, 148, 152)
JAW_R = (454, 323, 361, 288, 397, 365, 379, 378, 400, 377, 152)
FACE_UPPER_L = (234, 127, 162, 21, 54, 103, 67, 109, 10)
FACE_UPPER_R = (454, 356, 389, 251, 284, 332, 297, 338, 10)
#: The midline of the chin, from under the lower lip to the chin's lowest point.
CHIN_MIDLINE = (18, 200, 199, 175, 152)

# Nose: the bridge down the midline to the tip, and the base from each wing to the point
# under the tip (where the upper lip begins: an anchor there keeps the nose still while
# the lip moves).
NOSE_BRIDGE = (168, 6, 197, 195, 5, 4)
NOSE_BASE_L = (98, 97, 2)
NOSE_BASE_R = (327, 326, 2)

#: Points that do not move in speech: eye corners and the nose bridge. Lids blink, brows
#: rise, lips and jaw move; the bony eye corners and bridge stay put relative to the skull,
#: so a transform fitted on these alone registers a talking face without following its mouth.
STILL_POINTS = (33, 133, 263, 362, 168, 6, 197, 195)

#: Mesh points whose mirror images are each other (image left, image right), for measuring
#: how symmetric a face is. The midline points above are their own mirror images.
MIRROR_PAIRS = tuple(zip(
    LIP_OUTER_UPPER[:5] + LIP_OUTER_LOWER[1:5] + EYE_UPPER_L + EYE_LOWER_L[1:-1] + BROW_L
    + JAW_L[:-1] + FACE_UPPER_L[:-1],
    LIP_OUTER_UPPER[::-1][:5] + LIP_OUTER_LOWER[::-1][1:5] + EYE_UPPER_R + EYE_LOWER_R[1:-1] + BROW_R
    + JAW_R[:-1] + FACE_UPPER_R[:-1]))
#: Points on the face's midline.
MIDLINE_POINTS = (10, 168, 6, 197, 195, 5, 4, 2, 0, 13, 14, 17, 18, 200, 199, 175, 152)
