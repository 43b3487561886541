"""Wide-area search: the scenario's ``search:`` section (``section``, parsed
by ``spec``: area, base, fires), the plan flown as MAVLink missions
(``mission``), detections from the cameras' geometry (``sensing``) or their
frames (``image_detect``), the coverage map and the metrics (``participant``),
and a sweep's table of fleets (``sweep``)."""
