"""Running a city: imagery and a model in, the city graph and its files out, resumable
(``patch``: one window end to end; ``city`` and ``city_job``: the run and its per-patch work;
``city_blocks``: the city graph block by block; ``run``: the job with its outputs; ``predict``:
the ``predict`` and ``predict-patch`` commands' work; ``distributed``: the same on Dask)."""
