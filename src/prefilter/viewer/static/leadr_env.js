// The leadr-env / leadr-irradiance modes' data (docs/viewer.md): the environment as a lat-long
// RGBA32F texture whose mip levels are the exported solid-angle-weighted levels (read with
// texelFetch by leadr_env.glsl), and the irradiance map's node grid.

export const LEADR_ENV_METHODS = ['leadr-env', 'leadr-irradiance'];

function floatTexture(gl, levels, buf) {
  const t = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, t);
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
  const all = new Float32Array(buf);
  levels.forEach((lv, l) => gl.texImage2D(gl.TEXTURE_2D, l, gl.RGBA32F, lv.width, lv.height, 0,
    gl.RGBA, gl.FLOAT, all.subarray(lv.offset, lv.offset + lv.width * lv.height * 4)));
  for (const [k, v] of [[gl.TEXTURE_MIN_FILTER, levels.length > 1 ? gl.NEAREST_MIPMAP_NEAREST : gl.NEAREST],
                        [gl.TEXTURE_MAG_FILTER, gl.NEAREST], [gl.TEXTURE_BASE_LEVEL, 0],
                        [gl.TEXTURE_MAX_LEVEL, levels.length - 1],
                        [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]])
    gl.texParameteri(gl.TEXTURE_2D, k, v);
  return t;
}

// manifest entry `leadr_env` -> {env, irradiance, levels, texel}
export async function loadLeadrEnv(gl, base, entry, fetchOk) {
  const [env, irr] = await Promise.all([fetchOk(base + entry.env), fetchOk(base + entry.irradiance)]);
  return {
    env: floatTexture(gl, entry.levels, env),
    irradiance: floatTexture(gl, [{width: entry.irradiance_width, height: entry.irradiance_height,
                                   offset: 0}], irr),
    levels: entry.present ? entry.levels.length : 0,
    texel: entry.texel,
  };
}

// texture units for Viewer._bind (name, target, texture) and the snippet's scalar uniforms
export function leadrEnvUnits(gl, data) {
  return [['leadrEnv', gl.TEXTURE_2D, data.env], ['leadrIrradiance', gl.TEXTURE_2D, data.irradiance]];
}

export function bindLeadrEnv(viewer, data) {
  viewer._u('leadrEnvLevels', 'uniform1i', data.levels);
  viewer._u('leadrEnvTexel', 'uniform1f', data.texel);
}
