"""The solar market: the benchmark's first task (:data:`~solarchain_eval.solar.task.SOLAR_TASK`).

Its task object and episode metrics live here; its dataset pipeline (:mod:`solarchain_eval.data`),
dynamics (:mod:`solarchain_eval.market`) and environments (:mod:`solarchain_eval.envs`) are its
internals, which the generic wings reach only through the task.
"""
