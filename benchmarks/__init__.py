"""Speed and memory benchmarks of ffd: ``python -m benchmarks [--quick] [--only NAME]`` (``make bench``).

Every module ``benchmarks/bench_NAME.py`` defines ``run(quick: bool) -> list[dict]``: one dict per
measured case, the same keys in every row (the table's columns, in order). The runner prints one
Markdown table per module. Modules may also define ``TITLE`` (the table heading) and ``NOTES``
(a paragraph printed under the table: what is measured and how, targets, references).

Not run by the runner: ``python -m benchmarks.versus REV`` (the volume warp and ``ffd deform`` of a
1M-node mesh beside another revision of ffd, alternating, in one run: the gain as a ratio).
"""
