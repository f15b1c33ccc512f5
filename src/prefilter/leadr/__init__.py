"""LEADR mapping (Dupuy, Heitz, Iehl, Poulin, Neyret, Ostromoukhov 2013): linear slope moments of a
height map, mip-mapped by averaging, shaded as a non-centred anisotropic Beckmann microsurface
(closed form for point lights, Gaussian-grid integration for environment and irradiance maps).
"""

from prefilter.leadr.envmap import (EnvMap, IrradianceMap, procedural_env, sh9_irradiance,
                                    sh9_project)
from prefilter.leadr.maps import (
    CHANNELS,
    LeadrMaps,
    moments,
    shading_stats,
    slopes_from_height,
    slopes_from_normals,
    stats_to_moments,
)
from prefilter.leadr.shading import (
    artificial_micronormal,
    diffuse_directional,
    diffuse_irradiance,
    diffuse_sh,
    diffuse_shadowing,
    env_specular,
    gaussian_grid,
    grid_normals,
    point_light,
    schlick,
    shadowing_ratio,
)

__all__ = [
    "CHANNELS", "EnvMap", "IrradianceMap", "LeadrMaps", "artificial_micronormal",
    "diffuse_directional", "diffuse_irradiance", "diffuse_sh", "diffuse_shadowing", "env_specular",
    "gaussian_grid", "grid_normals", "moments", "point_light", "procedural_env", "schlick",
    "sh9_irradiance", "sh9_project", "shading_stats", "shadowing_ratio", "slopes_from_height",
    "slopes_from_normals", "stats_to_moments",
]
