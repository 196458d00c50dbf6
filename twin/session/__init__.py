"""A run session: what one use of the machine is, from the request to its record.

``setup`` (the run spec, ``prepare``: machine, controller model, program, driver),
``run`` (the lock-step and paced loops), ``run_end`` (stop signals, the final status),
``record`` (the run record written atomically), ``folder`` (the runs folder),
``dry_run`` (the plan alone, no drives), ``experiments`` (step and ramp responses).
"""
