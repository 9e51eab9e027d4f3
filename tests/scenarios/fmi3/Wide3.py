"""An FMI 3.0 co-simulation FMU with 64-bit integer parameters (built with pythonfmu3 at test
time): y = big mod 1000 + ubig mod 1000 (the low digits of all 64 bits), `steps` counts the
communication steps, the outputs `wide` = big + steps (Int64) and `uwide` = 2^40 + steps (UInt64)."""

from pythonfmu3 import Float64, Fmi3Causality, Fmi3Slave, Fmi3Variability, Int32, Int64, UInt64


class Wide3(Fmi3Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.author = "multirate-master tests"
        self.description = "64-bit integer parameters (FMI 3.0)"
        self.time = 0.0
        self.big = 0
        self.ubig = 0
        self.y = 0.0
        self.steps = 0
        self.wide = 0
        self.uwide = 0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent))
        fixed = dict(causality=Fmi3Causality.parameter, variability=Fmi3Variability.fixed)
        self.register_variable(Int64("big", **fixed))
        self.register_variable(UInt64("ubig", **fixed))
        self.register_variable(Float64("y", causality=Fmi3Causality.output))
        discrete = dict(causality=Fmi3Causality.output, variability=Fmi3Variability.discrete)
        self.register_variable(Int32("steps", **discrete))
        self.register_variable(Int64("wide", **discrete))
        self.register_variable(UInt64("uwide", **discrete))

    def do_step(self, current_time, step_size):
        self.y = float(self.big % 1000 + self.ubig % 1000)
        self.steps += 1
        self.wide = self.big + self.steps
        self.uwide = 2**40 + self.steps
        return True
