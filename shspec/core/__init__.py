"""The plumbing every layer of shspec stands on: argument checks, atomic files and output folders, thread and
process control, resource limits, damping schedules and plot style.  Nothing here knows about spectra."""
