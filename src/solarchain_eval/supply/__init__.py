"""The supply-chain allocation market: the template's second task (docs/tasks/supply_chain.md).

:data:`~.task.SUPPLY_TASK` is its face to the generic wings; :func:`~.build.build_supply_dataset`
builds its dataset; :class:`~.env.SupplyChainEnv` and :class:`~.vector.SupplyChainVectorEnv` are
its environments (``SupplyChainEval-v0``).
"""
