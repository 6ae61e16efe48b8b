"""The `usd_preview_lobe` BSDF plugin: our material with UsdPreviewSurface's specular lobe, for
measuring what the USD export's roughness mapping changes (bench/export.py).

GGX D and separable Smith G at alpha = r^2 = sqrt(ka) (r = ka^(1/4), export/roughness.py),
everything else as `milo`; sampled and weighted as `milo` (Beckmann half vectors), so the
estimate is unbiased and its noise follows milo's: the same seed gives correlated noise, and the
difference of two renders is the lobe's. Properties: those of `milo` (milo.py).
"""

from __future__ import annotations

import drjit as dr


def make_class(milo):
    """The `usd_preview_lobe` class for the current variant, derived from its `milo` class."""

    class UsdPreviewLobe(milo):
        def _eval_pdf(self, si, wo, active):
            _, pdf = milo._eval_pdf(self, si, wo, active)  # the density sample() draws from
            view, light = self._local(si, wo)
            kd, ks, ka, _ = self._params(si, active)
            ci, co = light.z, view.z
            valid = active & (ci > 0) & (co > 0)
            _, ch, wih, lobe = self._half_vector(view, light, valid)
            c2 = dr.square(ch)
            d = ka / (dr.pi * dr.square(c2 * (ka - 1.0) + 1.0))  # GGX with alpha^2 = ka

            def g1(c):  # Smith's masking for a direction at cos c > 0 (c = 1 where invalid)
                c2 = dr.square(dr.select(valid, c, 1.0))
                return 2.0 / (1.0 + dr.sqrt(1.0 + ka * (1.0 - c2) / c2))

            f90 = dr.minimum(1.0, 50.0 * ks)
            fresnel = ks + (f90 - ks) * dr.power(dr.maximum(1.0 - wih, 0.0), 5)
            specular = dr.select(lobe, fresnel * (d * g1(ci) * g1(co) / (4.0 * dr.select(valid, co, 1.0))), 0.0)
            return dr.select(valid, kd * (ci * dr.inv_pi) + specular, 0.0), pdf

    return UsdPreviewLobe
