"""Scrambled Halton sampling: a low-discrepancy point set of any size, sample statistics or a
least-squares chaos fit as for the other sampling designs."""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np
from pydantic import Field

from pcmb.chaos.nodes import NodeSet, unit_nodes
from pcmb.designs.sampling import Sampling, SamplingSettings
from pcmb.result import Design

__all__ = ["HaltonSampling", "HaltonSettings"]


class HaltonSettings(SamplingSettings):
    """``method: {kind: halton, samples, seed, fit, order}``."""

    kind: Literal["halton"] = Field(description="how nodes are made (a registered design)")


class HaltonSampling(Sampling):
    """``method: {kind: halton, samples, seed, fit, order}``: the first ``samples`` points of
    a Halton sequence scrambled with ``seed`` (scipy.stats.qmc.Halton), mapped through each
    input's germ quantile. Unlike Sobol' points, any number of points keeps its balance."""

    Settings = HaltonSettings

    def nodes(self) -> NodeSet:
        from scipy.stats import qmc  # deferred: scipy.stats is slow to import

        n = len(self.distributions)
        halton = qmc.Halton(d=n, scramble=True, rng=np.random.default_rng(self.seed))
        return unit_nodes(self.distributions, halton.random(self.samples))

    def record(self) -> Design:
        return dataclasses.replace(super().record(), grid="halton")
