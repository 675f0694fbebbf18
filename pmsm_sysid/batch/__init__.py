"""Batches of recordings for ``fleet``: which recordings and axes (:mod:`.inputs`), the
table on disk (:mod:`.store`, Parquet), and where the work runs (:mod:`.cluster`, Dask
distributed). Needs the ``[fleet]`` extra for the last two; import the modules directly."""
