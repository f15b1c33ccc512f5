// Procedural noise driver (Heitz et al. 2013, section 4.2; prefilter.colormap.kernels
// _noise_kernel): the filtered noise value is the caller's anisotropic mean of the noise mip
// chain; its std is the generator's std at the footprint's area LOD
// (log2(sqrt(major minor)) in texels), interpolated linearly in variance between levels
// (texture.NoiseStd). CM_NOISE_LEVELS / CM_NOISE_VAR are written in by glsl_drivers.py.
float colormapNoiseSigma(float areaLod) {
    int nl = CM_NOISE_LEVELS;
    float t = clamp(areaLod, 0.0, float(nl - 1));
    int l0 = nl > 1 ? min(int(t), nl - 2) : 0;
    float f = t - float(l0);
    float v = CM_NOISE_VAR[l0] * (1.0 - f) + CM_NOISE_VAR[min(l0 + 1, nl - 1)] * f;
    return sqrt(max(v, 0.0));
}
