"""The `milo` BSDF plugin: our material model (docs/renderer.md, "Material model") in Mitsuba.

f = kd/pi + D F G / (4 ci co): Beckmann D (ka = alpha^2), Schlick F with the F90 = min(1, 50 ks)
clamp, V-cavity G, two-sided; kd, ks, ka read from textures (textures.py). It follows the
kernel (kernels/bsdf.h `bsdf_cos`, `specular_cos`, `pdf_specular`) case by case, the degenerate
ones included: nothing where ci <= 0 or co <= 0, no specular lobe where the half vector is
undefined (|wi + wo|^2 <= 1e-12) or n.h <= 0 or wi.h <= 0. Every division has a denominator that
is not 0 even where its result is then discarded: `scalar_rgb` runs this code on Python floats,
where a division by zero raises instead of giving inf.

Mitsuba classes differ per variant, so the class is made (and registered, variant.py) once per
variant, after mi.set_variant.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .textures import bitmap_texture, constant_map, texture_property

KA_MIN = 1e-6  # lowest roughness of the model (render/bsdf.py clamps ka there too)
HALF_VECTOR_MIN_LEN2 = 1e-12  # kernels/bsdf.h: below it, wi + wo has no direction


def milo_bsdf(kd, ks, ka) -> dict:
    """A `milo` BSDF dict; kd, ks are (H, W, 3) maps or RGB values, ka an (H, W) map or a float."""
    return {
        "type": "milo",
        "kd": bitmap_texture(constant_map(kd, 3)),
        "ks": bitmap_texture(constant_map(ks, 3)),
        "ka": bitmap_texture(constant_map(ka, 1)),
    }


def make_class():
    """The `milo` BSDF class for the current variant."""

    class MiloBSDF(mi.BSDF):
        """f = kd/pi + D(h) F(wi.h) G / (4 ci co); Mitsuba's si.wi is our wo, its wo our wi.

        Sampling: one-sample mixture of cosine-weighted diffuse and Beckmann half-vector
        sampling, chosen in proportion to luminance(kd) and luminance(ks) (= F at normal
        incidence); pdf() returns the mixture density, so eval/pdf/sample are consistent.
        """

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.kd = texture_property(props, "kd", 0.5, channels=3)
            self.ks = texture_property(props, "ks", 0.0, channels=3)
            self.ka = texture_property(props, "ka", 0.1, channels=1)
            sides = mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            diffuse = mi.BSDFFlags.DiffuseReflection | sides
            glossy = mi.BSDFFlags.GlossyReflection | sides
            self.m_components = [diffuse, glossy]
            self.m_flags = diffuse | glossy

        # -- the pieces ------------------------------------------------------------------------
        def _params(self, si, active):
            kd = self.kd.eval(si, active)
            ks = self.ks.eval(si, active)
            ka = dr.maximum(self.ka.eval_1(si, active), KA_MIN)
            lum_d, lum_s = mi.luminance(kd), mi.luminance(ks)
            total = lum_d + lum_s
            p_spec = dr.select(total > 0, lum_s / dr.select(total > 0, total, 1.0), 0.0)
            return kd, ks, ka, p_spec

        @staticmethod
        def _beckmann_d(h, ka, lobe):
            """Beckmann D at the half vector h (local frame); 0 where `lobe` is false, as the
            kernel's specular term there (n.h <= 0 included: tan^2 would divide by 0)."""
            ch2 = dr.select(lobe, dr.square(h.z), 1.0)
            tan2 = (dr.square(h.x) + dr.square(h.y)) / ch2  # exact at small angles
            return dr.select(lobe, dr.exp(-tan2 / ka) / (dr.pi * ka * dr.square(ch2)), 0.0)

        @staticmethod
        def _local(si, wo):
            """Our (wo, wi) in the frame flipped to the side of the viewer."""
            flip = si.wi.z < 0
            view = mi.Vector3f(si.wi.x, si.wi.y, dr.abs(si.wi.z))
            light = mi.Vector3f(wo.x, wo.y, dr.select(flip, -wo.z, wo.z))
            return view, light

        @staticmethod
        def _half_vector(view, light, valid):
            """(h, n.h, wi.h, lobe): the half vector and where the specular lobe is defined
            (kernels/bsdf.h specular_cos: |wi + wo|^2 > 1e-12, n.h > 0, wi.h > 0)."""
            hsum = light + view
            len2 = dr.squared_norm(hsum)
            defined = valid & (len2 > HALF_VECTOR_MIN_LEN2)
            h = hsum * dr.rsqrt(dr.select(defined, len2, 1.0))
            ch, wih = h.z, dr.dot(light, h)  # wi.h = wo.h
            return h, ch, wih, defined & (ch > 0) & (wih > 0)

        def _eval_pdf(self, si, wo, active):
            view, light = self._local(si, wo)
            kd, ks, ka, p_spec = self._params(si, active)
            ci, co = light.z, view.z
            valid = active & (ci > 0) & (co > 0)
            h, ch, wih, lobe = self._half_vector(view, light, valid)
            wih_s, co_s = dr.select(lobe, wih, 1.0), dr.select(valid, co, 1.0)  # never 0
            d = self._beckmann_d(h, ka, lobe)
            g = dr.minimum(1.0, dr.minimum(2.0 * ch * co / wih_s, 2.0 * ch * ci / wih_s))
            f90 = dr.minimum(1.0, 50.0 * ks)
            fresnel = ks + (f90 - ks) * dr.power(dr.maximum(1.0 - wih, 0.0), 5)
            # f ci with the specular part as D G F / (4 co): ci co can underflow at grazing angles
            value = dr.select(valid, kd * (ci * dr.inv_pi) + fresnel * (d * g / (4.0 * co_s)), 0.0)
            pdf = (1.0 - p_spec) * ci * dr.inv_pi + p_spec * d * ch / (4.0 * wih_s)
            pdf = dr.select(valid, pdf, 0.0)
            return value, pdf

        # -- the mi.BSDF interface -------------------------------------------------------------
        def eval(self, ctx, si, wo, active=True):
            return self._eval_pdf(si, wo, active)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(si, wo, active)[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(si, wo, active)

        def sample(self, ctx, si, sample1, sample2, active=True):
            flip = si.wi.z < 0
            view = mi.Vector3f(si.wi.x, si.wi.y, dr.abs(si.wi.z))
            _, _, ka, p_spec = self._params(si, active)
            use_spec = sample1 < p_spec

            diffuse_dir = mi.warp.square_to_cosine_hemisphere(sample2)
            tan2 = -ka * dr.log(1.0 - sample2.x)
            cos_h = dr.rsqrt(1.0 + tan2)
            sin_h = dr.safe_sqrt(1.0 - dr.square(cos_h))
            sin_phi, cos_phi = dr.sincos(2.0 * dr.pi * sample2.y)
            h = mi.Vector3f(sin_h * cos_phi, sin_h * sin_phi, cos_h)
            spec_dir = 2.0 * dr.dot(view, h) * h - view

            light = dr.select(use_spec, spec_dir, diffuse_dir)
            wo = mi.Vector3f(light.x, light.y, dr.select(flip, -light.z, light.z))

            value, pdf = self._eval_pdf(si, wo, active)
            ok = active & (pdf > 0)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = wo
            bs.pdf = dr.select(ok, pdf, 0.0)
            bs.eta = 1.0
            bs.sampled_component = dr.select(use_spec, mi.UInt32(1), mi.UInt32(0))
            bs.sampled_type = dr.select(
                use_spec, mi.UInt32(+mi.BSDFFlags.GlossyReflection), mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            )
            weight = dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)
            return bs, weight

        def traverse(self, callback):
            callback.put_object("kd", self.kd, mi.ParamFlags.Differentiable)
            callback.put_object("ks", self.ks, mi.ParamFlags.Differentiable)
            callback.put_object("ka", self.ka, mi.ParamFlags.Differentiable)

        def to_string(self):
            return f"MiloBSDF[kd={self.kd}, ks={self.ks}, ka={self.ka}]"

    return MiloBSDF
