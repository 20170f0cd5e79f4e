"""Frozen configurations of the differentiable multi-view edge model (thesis Ch. 7)."""

from __future__ import annotations

import equinox as eqx
from jaxtyping import Array

from .._fields import check_fields, hyperparameter, static


def _check_levels(levels) -> None:
    msg = (
        "RenderConfig.tile_levels must be ((capacity, fraction), ...) with int capacities "
        "increasing from >= 1, fractions in (0, 1] non-increasing and the first fraction 1.0"
    )
    try:
        caps = [c for c, _ in levels]
        fracs = [float(f) for _, f in levels]
    except (TypeError, ValueError) as err:
        raise ValueError(f"{msg}; got {levels!r}") from err
    ok = bool(caps) and all(isinstance(c, int) and c >= 1 for c in caps)
    ok = ok and all(b > a for a, b in zip(caps, caps[1:], strict=False))
    ok = ok and fracs[0] == 1.0 and all(0.0 < f <= 1.0 for f in fracs)
    ok = ok and all(b <= a for a, b in zip(fracs, fracs[1:], strict=False))
    if not ok:
        raise ValueError(f"{msg}; got {levels!r}")


class RenderConfig(eqx.Module):
    """Splatting and transmittance compositing (eqs 7.3–7.14).

    Attributes:
        sigma_label: σ_S, standard deviation in pixels of the Gaussian depth-label splat
            (eq 7.4) and of the point density in xy (eq 7.7). Thesis: 1.3.
        sigma_weight: σ_λ, scale in pixels of the super-Gaussian label weight (eq 7.6).
            Thesis: 0.71.
        weight_order: p, integer order of the super-Gaussian ``exp(-(r²/2σ_λ²)^p)``, >= 1
            (static: it selects the kernel's form). Thesis: 2.
        sigma_depth: σ_Z, standard deviation of a point's density along the ray, in label
            units (eq 7.7). Thesis: 1.0.
        density: ρ, peak density of a point (eq 7.7); with ``density * sigma_depth * √(2π)``
            large, a point is opaque near its centre.
        depth_span: half-width, in units of σ_Z, of the depth interval ``N_x`` sampled by the
            quadrature of eq 7.14 (the local bounds ``[0, t]`` of eq 7.9 with ``μ_z = t/2``).
        radius: half-size of the square splat support; ``2 * radius + 1`` pixels wide
            (thesis: 3, a 7×7 kernel).
        depth_samples: number of quadrature samples per point along the ray (thesis: 8).
        tile_size: edge length in pixels of the square screen tiles rendered in parallel;
            >= ``2 * radius + 1`` so that a point touches at most 2×2 tiles.
        tile_levels: per-tile capacities as ``((c_1, f_1), (c_2, f_2), ...)``, capacities
            increasing, fractions decreasing, ``f_1 = 1``: every tile keeps its ``c_1``
            nearest points, the ``f_2`` fraction of tiles holding the most points keeps up to
            ``c_2``, and so on; points beyond their tile's capacity (the farthest) are dropped
            and counted in ``RenderResult.overflow``. The work per pixel is
            ``c_1 + Σ_k f_k (c_k - c_(k-1))`` point evaluations. A single capacity ``C`` is
            ``((C, 1.0),)``. With the 8-pixel default tiles a tile sees at most
            ``(8 + 6)² = 196`` pixel-centred points.
        nearer: ``"larger"`` when a larger label is nearer (disparity, SPEC §0) or
            ``"smaller"`` for metric depth labels.
        label_mix: how S^Z mixes the labels of the points covering a pixel:
            ``"opacity"`` — weighted by each point's composited opacity ``a_p`` (eq 7.13,
            normalised by α); ``"weight"`` — weighted by each point's visible label weight
            ``T_before λ_p`` (the same weights as λ^Z, so that the data term of eq 7.2 equals
            ``Σ_p Σ_q T_before λ_p (D_q - Z_p)²`` up to a constant).
    """

    sigma_label: Array = hyperparameter(1.3, differentiable=True, lower=0.0, lower_open=True)
    sigma_weight: Array = hyperparameter(0.71, differentiable=True, lower=0.0, lower_open=True)
    weight_order: int = static(2, lower=1, upper=16)
    sigma_depth: Array = hyperparameter(1.0, differentiable=True, lower=0.0, lower_open=True)
    density: Array = hyperparameter(2.0, differentiable=True, lower=0.0, lower_open=True)
    depth_span: Array = hyperparameter(3.0, differentiable=True, lower=0.0, lower_open=True)
    radius: int = static(3, lower=1, upper=64)
    depth_samples: int = static(8, lower=0, upper=1024)
    tile_size: int = static(8, lower=1, upper=1024)
    tile_levels: tuple[tuple[int, float], ...] = eqx.field(
        static=True, default=((48, 1.0), (96, 0.4), (200, 0.2))
    )
    nearer: str = static("larger", choices=("larger", "smaller"))
    label_mix: str = static("weight", choices=("opacity", "weight"))

    @property
    def tile_capacity(self) -> int:
        """The most points a tile keeps (the last capacity of ``tile_levels``)."""
        return int(self.tile_levels[-1][0])

    def __check_init__(self):
        check_fields(self)
        if not isinstance(self.tile_size, int) or self.tile_size < 2 * self.radius + 1:
            raise ValueError(
                f"RenderConfig.tile_size must be an int >= 2 * radius + 1 = "
                f"{2 * self.radius + 1}; got {self.tile_size!r}"
            )
        _check_levels(self.tile_levels)
