"""world: what exists in a scenario, apart from the vehicles and from how
cameras draw it: the ground (``ground``: its texture, an image or GeoTIFF,
the checks on every file it names, ``imagery`` and ``headers``, and the image
read and placed on the grid of ``image_grid``: a picture by ``picture``, a
georeferenced file by ``geotiff``), the targets (``targets``), the obstacles
(``obstacles``).

Its three sections (``ground:``, ``targets:``, ``obstacles:``, in
``sections``) add to the world, and so may any other section
(``Section.world``: the search adds its fires as targets);
``World.assemble`` (``model``) makes the one world every part reads
(``Scenario.world``): the renderer draws it, the vehicle classes read what
they need of it (``VehicleClass.with_world``), the search scores against it.
This part imports only the kernel (``cosim.core``) and ``cosim.errors``.
"""
