"""The sampling that the station's sensors share.

A sensor reads at its own rate: a periodic discrete update at 1 / rate,
offset 0, stores the reading and a counter of readings (the tick that
seeds its noise), and its outputs come from that state alone, so they
hold between readings and have no direct feedthrough. An initialization
event stores the reading of the inputs at the start without advancing the
counter (Simulator.Initialize runs no periodic update; the update at
t = 0 then stores the reading again, with the tick unchanged).
"""


class SampledReading:
    """A mixin for a LeafSystem that samples a reading.

    The system calls `_declare_sampling` in its constructor and implements
    `_read(context, tick)`, the reading of its current inputs at counter
    `tick`; `_stored_reading(context)` is the last reading, for outputs.
    """

    def _declare_sampling(self, initial, rate):
        """Declares the reading (starting at `initial`), its counter and
        the events; returns the prerequisites of an output computed from
        the reading."""
        self._reading = self.DeclareDiscreteState(initial)
        self._tick = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / rate, 0.0,
                                                self._sample)
        self.DeclareInitializationDiscreteUpdateEvent(self._store_reading)
        return {self.discrete_state_ticket(self._reading)}

    def initialize_reading(self, context):
        """Stores in `context` the reading of its current inputs, at the
        current counter (left as it is)."""
        self._store_reading(context, context.get_mutable_discrete_state())

    def _tick_of(self, context):
        return context.get_discrete_state(self._tick).GetAtIndex(0)

    def _store_reading(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._reading).set_value(
            self._read(context, self._tick_of(context)))

    def _sample(self, context, discrete_state):
        tick = self._tick_of(context)
        discrete_state.get_mutable_vector(self._reading).set_value(
            self._read(context, tick))
        discrete_state.get_mutable_vector(self._tick).SetAtIndex(0, tick + 1)

    def _stored_reading(self, context):
        return context.get_discrete_state(self._reading).CopyToVector()

    def _stored_reading_view(self, context):
        """The last reading as a read-only view into `context`: to be
        used (or copied) before the context changes."""
        view = context.get_discrete_state(self._reading).get_value()
        view.flags.writeable = False
        return view
