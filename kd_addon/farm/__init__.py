"""Rendering a frame range on a Dask cluster (`--dask ADDRESS`, `--local-workers N`; docs/farm.md).

client.py runs on the user's machine: it splits the frames into contiguous chunks, submits one task a
chunk, writes the frames the workers stream back and one report.json. tasks.py runs on the workers: it
renders a chunk with sequence.SequenceJob, as the in-process path does. bootstrap.py is what the
scheduler sends: it checks a worker's bpy and KD Preview before importing tasks.py. cluster.py connects
or starts the cluster. Nothing here is imported unless one of those options is given: Dask is an
optional extra (pyproject.toml `farm`), never bundled with the extension.
"""
