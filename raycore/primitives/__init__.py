"""Ray intersection kernels, one module per shape; :mod:`.analytic` gathers the analytic ones."""
