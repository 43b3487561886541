"""core: the kernel every part may import, and that imports nothing of cosim
but ``cosim.errors``: units and constants (``units``), the exact WGS-84
frame (``geo``), the state layout and a vehicle's spec (``state``), the
camera geometry (``camera``) and the display geometry (``display``: screen
pixels, millimetres and visual angles). Nothing here knows a vehicle class,
a backend, a scenario section or a protocol.
"""
