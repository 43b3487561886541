"""renderer: per-vehicle cameras over the world's ground with 3-D targets;
frames to video plus a ground-truth record per frame.

Owns the ``cameras:`` section (``section``, parsed by ``config``), the ground
a frame draws (``ground``: the procedural texture ``texture``, its fine
detail ``detail`` and its ``noise``, its tiles in memory ``pyramid`` and on disk ``tile_cache``, the
imagery drawn over it ``image_layers``), target drawing and ground truth
(``targets``), the obstacles' buildings and shadows (``buildings``,
``shadows``), the procedural ground's trees in 3-D (``canopy``, filled by
``canopy_pass``), one frame (``frame``) and its ground truth (``truth``), the
operator view (``operator``), video (``video``, ``stream``), the render pool
(``render_pool``), what the cameras write (``outputs``) and the loop's hooks
(``participant``). What it draws is
the scenario's world (``cosim.world``, which reads and places the ground
imagery) seen through the kernel's camera model (``cosim.core.camera``). It
reads the loop's state array at exchange ticks and never touches the FDM pool,
the logs' files or other participants.
Frames depend only on the scenario, the seed and the simulated pose at the
frame's tick: never on wall-clock time or the number of render workers.
"""
