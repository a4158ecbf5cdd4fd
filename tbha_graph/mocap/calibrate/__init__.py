"""Camera calibration nodes: Tsai's coplanar 5-point method on the T-pose torso (``calibrate.tsai_coplanar``),
PnP with known intrinsics (``calibrate.pnp``), a camera read from a file (``calibrate.known``) and
intrinsics from a checkerboard clip (``calibrate.checkerboard``), all output a
:class:`~tbha_graph.mocap.camera.CameraModel`; the focal length from the room's straight lines
(``calibrate.vanishing_points``) outputs a :class:`~tbha_graph.mocap.bundles.lens.LensEstimate` for the solver."""
