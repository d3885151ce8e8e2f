"""The spatial craft the tests share: a hub with products of inertia carrying one array along
``y`` (soft along its normal ``z``, 100 times stiffer laterally), as keyword arguments and as
the start of a scene."""

import textwrap

#: Hub inertia about its centre, hub frame, kg m^2.
INERTIA = [[1.30, 0.05, -0.02], [0.05, 1.16, 0.03], [-0.02, 0.03, 1.45]]
#: The array's ``SpatialAppendage`` fields.
WING = dict(name="wing_a", direction=(0, 1, 0), normal=(0, 0, 1), length=1.8, density=2766.0,
            area=2.5e-4, youngs_modulus=6.9e10, second_moment=5.2083e-10,
            second_moment_lateral=5.2083e-8, shear_modulus=2.6e10, torsion_constant=1.9531e-9)
#: The hub and the array as scene tables (a scene goes on with its other tables).
CRAFT_TOML = textwrap.dedent("""\
    [hub]
    inertia = [[1.30, 0.05, -0.02], [0.05, 1.16, 0.03], [-0.02, 0.03, 1.45]]
    radius = 0.06

    [[appendages]]
    name = "wing_a"
    direction = [0.0, 1.0, 0.0]
    normal = [0.0, 0.0, 1.0]
    length = 1.8
    density = 2766.0
    area = 2.5e-4
    youngs_modulus = 6.9e10
    second_moment = 5.2083e-10
    second_moment_lateral = 5.2083e-8
    shear_modulus = 2.6e10
    torsion_constant = 1.9531e-9

    """)
