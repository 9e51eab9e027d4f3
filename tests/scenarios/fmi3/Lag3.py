"""An FMI 3.0 co-simulation FMU for the scenario tests (built with pythonfmu3 at test time).

First-order lag y' = (u - y) / tau, explicit Euler over each communication step, and an
Int32 output `steps` (communication steps taken) to test type checks across FMI versions.
Its ModelStructure gives no dependencies for y, which means y depends on every input.
"""

from pythonfmu3 import Float64, Fmi3Causality, Fmi3Slave, Fmi3Variability, Int32


class Lag3(Fmi3Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.author = "multirate-master tests"
        self.description = "first-order lag (FMI 3.0)"
        self.time = 0.0
        self.tau = 1.0  # s
        self.u = 0.0
        self.y = 0.0
        self.steps = 0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent))
        self.register_variable(
            Float64("tau", causality=Fmi3Causality.parameter, variability=Fmi3Variability.fixed)
        )
        self.register_variable(Float64("u", causality=Fmi3Causality.input))
        self.register_variable(Float64("y", causality=Fmi3Causality.output))
        self.register_variable(
            Int32("steps", causality=Fmi3Causality.output, variability=Fmi3Variability.discrete)
        )

    def do_step(self, current_time, step_size):
        self.y += step_size * (self.u - self.y) / self.tau
        self.steps += 1
        return True
