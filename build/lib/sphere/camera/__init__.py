"""The camera side of the hybrid tracker: a pinhole camera with lens distortion (:mod:`.model`), the exact
perspective geometry of a sphere's image (:mod:`.sphere_geometry`), a virtual camera that renders BROAD
trials as a webcam would see them (:mod:`.render`), the ball detector (:mod:`.detect`) and the intrinsic
calibration from board images (:mod:`.calibration`).

OpenCV (``opencv-python-headless``, the ``camera`` extra) is needed by the renderer, detector and
calibration; the geometry is pure numpy.
"""
