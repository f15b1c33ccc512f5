"""A scene as Mitsuba 3 XML (``mi.load_file``), meshes as binary PLY, environments as EXR, so a
user can path-trace it in Mitsuba (``prefilter export-mitsuba SCENE.json --out DIR``).

Conventions (``docs/pathtracing.md``, "Mitsuba export"):

* camera: ``perspective`` with ``fov_axis="y"`` (the scene's ``fov`` is vertical) and
  ``look_at(origin, target, up)``; ``hdrfilm`` with a ``box`` filter (a pixel is the mean over
  its square, as every method renders it), ``rgb``.
* integrator: ``path`` with ``max_depth = bounces + 1`` (Mitsuba counts the camera segment) and
  ``hide_emitters = true``: like the renderer, pixels that see nothing are black and lights are
  not seen by camera rays. Russian roulette from depth ``rr_depth = 3``.
* material (``base_color / pi cos + F G D / (4 wo_z)``): a ``blendbsdf`` of weight
  ``w = max f0 / (max f0 + max base_color)`` between a ``diffuse`` of reflectance
  ``base_color / (1 - w)`` and a ``roughconductor`` (``distribution="ggx"``, ``alpha_u =
  alpha_x`` along the tangent, ``alpha_v = alpha_y``, ``material="none"``: a perfect reflector
  times ``specular_reflectance = f0 / w``), i.e. their sum, in a ``twosided`` wrapper (surfaces
  are two-sided); Mitsuba's reflectances are at most 1, so the sum is exact where
  ``max base_color + max f0 <= 1`` (else clipped, noted in the XML). Exact for ``f0 = 1`` and
  for ``f0 = 0`` up to Schlick's ``(1 - cos)^5`` term; for other ``f0`` Schlick's Fresnel
  becomes the constant ``f0``; Mitsuba's masking is the separable Smith ``G1 G1``, the
  renderer's the height-correlated one (a few per cent apart at grazing angles). Textures
  (normal, height and colour maps) are not exported (listed in the XML's comments).
* shapes: planes as ``rectangle`` (``to_world`` columns ``t size_x / 2``, ``b size_y / 2``,
  ``n``: its ``+z`` normal is the plane's normal), spheres as ``sphere``, meshes as PLY (world
  space, the renderer's vertex normals and UVs, ``v`` flipped back to the OBJ/PLY convention).
* quad lights: a ``rectangle`` (or, for other convex quads, a two-triangle PLY ``v0 v1 v2``,
  ``v0 v2 v3``) with an ``area`` emitter; both emit along ``(v1 - v0) x (v2 - v0)``, the
  renderer's one-sided convention. Point lights: ``point`` (``intensity``), directional lights:
  ``directional`` (``irradiance``, ``direction`` of travel).
* environment: ``envmap`` of an EXR of the image times ``scale``, ``to_world`` a rotation by 180
  degrees about ``y``: Mitsuba maps ``u = atan2(x, -z) / 2 pi``, the scene format
  ``u = atan2(-x, z) / 2 pi`` (both ``v = acos(y) / pi``, row 0 the zenith).
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from prefilter.errors import PrefilterError

__all__ = ["export_mitsuba", "write_ply"]


def write_ply(path, vertices, faces, normals=None, uv=None) -> Path:
    """A binary little-endian PLY with ``vertices (V, 3)``, optional ``normals (V, 3)`` and
    ``uv (V, 2)`` (as ``u, v``), triangles ``faces (F, 3)``; written atomically, and not at all
    when the file already holds the same bytes."""
    v = np.asarray(vertices, np.float32)
    props = [("x", v[:, 0]), ("y", v[:, 1]), ("z", v[:, 2])]
    if normals is not None:
        n = np.asarray(normals, np.float32)
        props += [("nx", n[:, 0]), ("ny", n[:, 1]), ("nz", n[:, 2])]
    if uv is not None:
        t = np.asarray(uv, np.float32)
        props += [("u", t[:, 0]), ("v", t[:, 1])]
    f = np.asarray(faces, np.int32)
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(v)}"]
    head += [f"property float {name}" for name, _ in props]
    head += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    vrec = np.stack([a for _, a in props], -1).astype("<f4")
    frec = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    frec["n"] = 3
    frec["i"] = f
    data = (("\n".join(head) + "\n").encode("ascii") + vrec.tobytes() + frec.tobytes())
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not (path.is_file() and path.read_bytes() == data):  # shipped files stay untouched
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)
    return path


def _vec(a) -> str:
    return ", ".join(f"{float(x):.9g}" for x in np.asarray(a).reshape(-1))


def _rgb(name, value) -> str:
    return f'<rgb name="{name}" value="{_vec(np.broadcast_to(value, 3))}"/>'


def _matrix(m) -> str:
    return f'<transform name="to_world"><matrix value="{_vec(np.asarray(m))}"/></transform>'


def _frame_matrix(x, y, z, origin) -> np.ndarray:
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, origin
    return m


def _bsdf(mat, where: str, notes: list) -> str:
    """The material as ``twosided(blendbsdf(w, diffuse(base / (1 - w)), roughconductor(f0 /
    w)))`` with ``w = max f0 / (max f0 + max base)``: their sum. Mitsuba's reflectances are at
    most 1, so this is exact where ``max base + max f0 <= 1``; beyond, both are clipped (noted)."""
    sb, sf = float(np.max(mat.base_color)), float(np.max(mat.f0))
    w = 0.5 if sb + sf <= 0.0 else sf / (sb + sf)
    diff = mat.base_color / (1.0 - w) if w < 1.0 else np.zeros(3)
    spec = mat.f0 / w if w > 0.0 else np.zeros(3)
    if sb + sf > 1.0 + 1e-9:
        notes.append(f"{where}.material: max base_color + max f0 = {sb + sf:.3g} > 1 (Mitsuba's "
                     "reflectances are at most 1): both clipped, the export is darker")
    return ("<bsdf type=\"twosided\"><bsdf type=\"blendbsdf\">"
            f"<float name=\"weight\" value=\"{w:.9g}\"/>"
            f"<bsdf type=\"diffuse\">{_rgb('reflectance', np.clip(diff, 0, 1))}</bsdf>"
            "<bsdf type=\"roughconductor\"><string name=\"material\" value=\"none\"/>"
            "<string name=\"distribution\" value=\"ggx\"/>"
            f"<float name=\"alpha_u\" value=\"{mat.alpha_x:.9g}\"/>"
            f"<float name=\"alpha_v\" value=\"{mat.alpha_y:.9g}\"/>"
            f"{_rgb('specular_reflectance', np.clip(spec, 0, 1))}</bsdf>"
            "</bsdf></bsdf>")


def _untextured(mat, where: str) -> list[str]:
    return [f"{where}.material.{k}: not exported (Mitsuba gets the untextured material)"
            for k in ("normal_map", "height_map", "color_map") if getattr(mat, k) is not None]


def export_mitsuba(scene, out_dir, *, spp: int = 64, bounces: int = 4,
                   name: str = "scene.xml") -> Path:
    """Write ``scene`` (a path, ``example:NAME``, a dict or a loaded
    :class:`~prefilter.render.scene.Scene`) as Mitsuba 3 XML ``out_dir/name`` with its meshes
    (``meshes/*.ply``) and environments (``env*.exr``); returns the XML's path. ``spp``: the
    sampler's samples per pixel; ``bounces``: the path tracer's vertices (``max_depth =
    bounces + 1``). Conventions in the module docstring."""
    from prefilter.render.lights import quad_rectangle
    from prefilter.render.scene import Scene, load_scene
    from prefilter.texture.io import write_image

    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if not (isinstance(spp, int) and spp >= 1):
        raise PrefilterError(f"spp: expected an integer >= 1, got {spp!r}")
    if not (isinstance(bounces, int) and bounces >= 1):
        raise PrefilterError(f"bounces: expected an integer >= 1, got {bounces!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cam = scene.camera
    notes: list[str] = []
    x = ['<scene version="3.0.0">',
         f'<integrator type="path"><integer name="max_depth" value="{bounces + 1}"/>'
         '<integer name="rr_depth" value="3"/><boolean name="hide_emitters" value="true"/>'
         '</integrator>',
         '<sensor type="perspective"><string name="fov_axis" value="y"/>'
         f'<float name="fov" value="{cam.fov:.9g}"/>'
         f'<transform name="to_world"><lookat origin="{_vec(cam.origin)}" '
         f'target="{_vec(cam.target)}" up="{_vec(cam.up)}"/></transform>'
         f'<sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>'
         f'<film type="hdrfilm"><integer name="width" value="{cam.width}"/>'
         f'<integer name="height" value="{cam.height}"/>'
         '<string name="pixel_format" value="rgb"/><rfilter type="box"/></film></sensor>']
    for i, obj in enumerate(scene.objects):
        mat = obj.material
        notes += _untextured(mat, f"objects[{i}]")
        bsdf = _bsdf(mat, f"objects[{i}]", notes)
        if obj.type == "plane":
            b = np.cross(obj.normal, obj.tangent)
            m = _frame_matrix(obj.tangent * obj.size[0] / 2, b * obj.size[1] / 2, obj.normal,
                              obj.center)
            x.append(f'<shape type="rectangle" id="object{i}">{_matrix(m)}{bsdf}</shape>')
        elif obj.type == "sphere":
            x.append(f'<shape type="sphere" id="object{i}"><point name="center" '
                     f'value="{_vec(obj.center)}"/><float name="radius" '
                     f'value="{obj.radius:.9g}"/>{bsdf}</shape>')
        else:
            d = obj.data
            uv = None if d.uv is None else np.stack([d.uv[:, 0], 1.0 - d.uv[:, 1]], -1)
            rel = f"meshes/object{i}.ply"
            write_ply(out / rel, d.vertices, d.faces, d.normals, uv)
            x.append(f'<shape type="ply" id="object{i}"><string name="filename" '
                     f'value={quoteattr(rel)}/>{bsdf}</shape>')
    n_env = 0
    for i, light in enumerate(scene.lights):
        if light.type == "quad":
            if light.texture is not None:
                notes.append(f"lights[{i}].texture: not exported (the light is uniform)")
            emitter = f'<emitter type="area">{_rgb("radiance", light.radiance)}</emitter>'
            rect = quad_rectangle(light.vertices)
            v = light.vertices
            if rect is not None:
                ex, ey = v[1] - v[0], v[3] - v[0]
                n = np.cross(ex, ey)
                m = _frame_matrix(ex / 2, ey / 2, n / np.linalg.norm(n), v.mean(0))
                x.append(f'<shape type="rectangle" id="light{i}">{_matrix(m)}{emitter}</shape>')
            else:
                rel = f"meshes/light{i}.ply"
                write_ply(out / rel, v, [[0, 1, 2], [0, 2, 3]])
                x.append(f'<shape type="ply" id="light{i}"><string name="filename" '
                         f'value={quoteattr(rel)}/><boolean name="face_normals" value="true"/>'
                         f'{emitter}</shape>')
        elif light.type == "point":
            x.append(f'<emitter type="point"><point name="position" '
                     f'value="{_vec(light.position)}"/>{_rgb("intensity", light.intensity)}'
                     '</emitter>')
        elif light.type == "directional":
            x.append(f'<emitter type="directional"><vector name="direction" '
                     f'value="{_vec(light.direction)}"/>{_rgb("irradiance", light.irradiance)}'
                     '</emitter>')
        else:
            img = np.asarray(light.image.load(), np.float64)
            if img.ndim == 2:
                img = img[..., None]
            img = (np.repeat(img[..., :1], 3, 2) if img.shape[2] < 3 else img[..., :3])
            rel = f"env{n_env}.exr"
            n_env += 1
            write_image(out / rel, img * light.scale)
            rot = np.diag([-1.0, 1.0, -1.0, 1.0])
            x.append(f'<emitter type="envmap"><string name="filename" value={quoteattr(rel)}/>'
                     f'{_matrix(rot)}</emitter>')
    x.append("</scene>")
    head = "".join(f"<!-- {n.replace('--', '-')} -->\n" for n in notes)
    path = out / name
    path.write_text('<?xml version="1.0" encoding="utf-8"?>\n' + head + "\n".join(x) + "\n")
    return path
