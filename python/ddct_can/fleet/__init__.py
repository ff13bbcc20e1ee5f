"""ddct at fleet scale (issue 18): `ddct-fleet` runs thousands of `ddct gap diagnose` on Dask
distributed — a LocalCluster on this machine by default, an existing cluster with
`--scheduler tcp://HOST:8786` — one task per log, findings streamed into a Parquet dataset with
one file per log (keyed by the content hash of its records, so a rerun resumes), a failed log
an error row. See docs/fleet.md.
"""

from .campaign import FINDINGS_SCHEMA, Task, discover, run_campaign, run_sequential

__all__ = ["FINDINGS_SCHEMA", "Task", "discover", "run_campaign", "run_sequential"]
