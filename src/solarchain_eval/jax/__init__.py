"""Optional JAX backend: a jittable SolarChain environment with the gymnax API, and rejax training.

Install with ``pip install -e '.[jax]'`` in a clone of the repository. The environment runs the same
:func:`~solarchain_eval.market.dynamics.market_step` as the numpy environments, evaluated on
JAX arrays (see docs/jax.md). Importing this package without JAX raises an ``ImportError``
that says how to install it.
"""

from __future__ import annotations

try:
    import gymnax as _gymnax  # noqa: F401
    import jax as _jax  # noqa: F401
except ImportError as error:  # pragma: no cover - depends on the installation
    raise ImportError(
        f"the JAX backend needs the 'jax' extra ({error.name} is missing): pip install -e '.[jax]' in a clone of the repository"
    ) from None

from ..envs.jax_env import EnvParams, EnvState, SolarChainJaxEnv, make_env_params

__all__ = ["EnvParams", "EnvState", "SolarChainJaxEnv", "make_env_params"]
