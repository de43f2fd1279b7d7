"""ODE integration for Python models: explicit Runge–Kutta pairs stepped over a batch of nodes
(:mod:`.runge_kutta`) and stacked ODE models with their solvers (:mod:`.stacked_ode`)."""
