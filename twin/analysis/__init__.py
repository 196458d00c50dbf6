"""Analysis of runs: ``compare`` (acceleration laws side by side, the winner of every
figure), ``report`` (its PNG, table and recording) and ``studies`` (the seeds' results
reproduced, ``docs/RESULTS.md``).
"""
