"""Deflection prediction: dq = C_q J(q)^T W, from the gravity-free wrench
(moved from the sensor frame to the tool point in the base frame), the
Jacobian at the measured joint angles and the compensator's stiffness model
(which may differ from the plant's).  With lost motion or coupling in the
model, the transmission law of model/transmission.py: the extra twist of
the gears when the process torque adds to the static (gravity) torque they
already carry.  With the hysteretic play law (model/play_hysteresis.py)
the gears' positions in their gaps are this block's discrete state,
updated once per controller period from the gear torque it predicts."""

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem

from robstiff_drake.model.compensator import DeflectionModel


class DeflectionPrediction(LeafSystem):
    """Inputs ``process_wrench`` (6, sensor frame) and ``q`` (6, rad).
    Outputs ``dq`` (6, rad): the predicted joint deflection, and
    ``tool_wrench`` (6): the wrench at the tool point, base frame.
    With lost motion in the model, input ``static_torque`` (6, N*m): the
    torque the gears carry before the cut (gravity), from the controller's
    model; the lost motion acts only where the total torque changes sign.
    Each is recomputed only when an input changes (the tool wrench is
    computed by both: two cheap transforms cost less than a shared cache
    entry's extra call into Python).

    With the hysteretic play law, discrete state ``play_position`` (6, rad:
    each gear's position in its gap after the last period's torque),
    ``play_reference`` (6, rad: at the touch-off) and ``play_started``
    (1: 0 until the first update, which puts the gears at rest on the
    flank the static torque presses, as the station's touch-off does).
    ``dq`` is the law at the positions the current inputs lead to, and the
    update every ``period_s`` (the controller's, in step with the tick whose
    samples feed it) stores those positions: Drake's update sees the inputs
    held over the period just ended, the ones ``dq`` was computed from."""

    def __init__(self, *, predictor, tool_m, mount_rpy_deg=(0.0, 0.0, 0.0), lost_motion_rad=None,
                 coupling_c23_rad_per_Nm=0.0, take_up_Nm=None, law="smooth", friction_Nm=None, period_s=None,
                 controller_plant=None):
        """``predictor``: the compensator's DeflectionPredictor; ``tool_m``:
        the tool point in the flange frame (m); ``mount_rpy_deg``: the sensor
        frame's rotation on the flange (deg); ``law``, ``friction_Nm``:
        model/compensator.DeflectionModel's; ``period_s``: the controller's
        period (s; needed with the hysteretic law); ``controller_plant``:
        the controller's model, whose mass matrix at the first sample gives
        each link's inertia for its crossing of the gap (None: the law
        crosses at once)."""
        super().__init__()
        # the arithmetic: model/compensator.DeflectionModel (shared with the compensator process)
        self._model = DeflectionModel(predictor, tool_m, mount_rpy_deg, lost_motion_rad, coupling_c23_rad_per_Nm,
                                      take_up_Nm, law, friction_Nm)
        self._lost = self._model.lost
        self._w = self.DeclareVectorInputPort("process_wrench", 6)
        self._q = self.DeclareVectorInputPort("q", 6)
        deps = {self._w.ticket(), self._q.ticket()}
        self._static = None
        if self._lost is not None:
            self._static = self.DeclareVectorInputPort("static_torque", 6)
            deps.add(self._static.ticket())
        if self._model.hysteretic:
            if not period_s:
                raise ValueError("the hysteretic play law needs the controller's period (period_s)")
            self._pos = self.DeclareDiscreteState(6)
            self._ref = self.DeclareDiscreteState(6)
            self._started = self.DeclareDiscreteState(1)
            self._T = float(period_s)
            self._plant = controller_plant
            if controller_plant is not None:
                self._plant_context = controller_plant.CreateDefaultContext()
                self._rate = self.DeclareDiscreteState(6)
                self._inertia = self.DeclareDiscreteState(np.ones(6))
            self.DeclarePeriodicDiscreteUpdateEvent(float(period_s), 0.0, self._update_play)
            deps.add(self.xd_ticket())
        self.DeclareVectorOutputPort("dq", 6, self._calc_play_dq if self._model.hysteretic else self._calc_dq,
                                     prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("tool_wrench", 6, lambda c, o: o.SetFromVector(self._tool_wrench(c)[0]),
                                     prerequisites_of_calc=deps)

    @property
    def model(self):
        """Its arithmetic (model/compensator.DeflectionModel)."""
        return self._model

    def _tool_wrench(self, context):
        """(the wrench at the tool point, base frame, as a list; q)."""
        q = self._q.Eval(context)
        return self.tool_wrench_of(self._w.Eval(context), q), q

    def tool_wrench_of(self, process_wrench, q):
        """The wrench at the tool point (base frame, list of 6) for a process
        wrench in the sensor frame at joint angles q (rad)
        (model/compensator.DeflectionModel)."""
        return self._model.tool_wrench(process_wrench, q)

    def _calc_dq(self, context, output):
        static = self._static.Eval(context) if self._static is not None else None
        output.SetFromVector(np.asarray(self._model.dq(self._w.Eval(context), self._q.Eval(context), static)))

    def _play(self, context):
        """(tau_process, static torque, positions after the current inputs,
        reference, rates, inertia) of the hysteretic law (rates and inertia
        None without the controller's model)."""
        q = self._q.Eval(context)
        tau = self._model.process_torque(self._w.Eval(context), q)
        static = self._static.Eval(context)
        rates = inertia = None
        if context.get_discrete_state(self._started).GetAtIndex(0) == 0.0:
            pos = self._model.play_positions(tau, static)
            if self._plant is not None:
                self._plant.SetPositions(self._plant_context, q)
                rates, inertia = np.zeros(6), np.diag(self._plant.CalcMassMatrix(self._plant_context)).copy()
            return tau, static, pos, pos, rates, inertia
        pos = context.get_discrete_state(self._pos).value()
        ref = context.get_discrete_state(self._ref).value()
        if self._plant is None:
            return tau, static, self._model.play_positions(tau, static, pos), ref, None, None
        inertia = context.get_discrete_state(self._inertia).value()
        pos, rates = self._model.play_crossing(tau, static, pos, context.get_discrete_state(self._rate).value(),
                                               inertia, self._T)
        return tau, static, pos, ref, rates, inertia

    def _calc_play_dq(self, context, output):
        tau, static, pos, ref, _, _ = self._play(context)
        output.SetFromVector(self._model.play_dq(tau, static, pos, ref))

    def _update_play(self, context, discrete_state):
        _, _, pos, ref, rates, inertia = self._play(context)
        discrete_state.set_value(int(self._pos), pos)
        discrete_state.set_value(int(self._ref), ref)
        discrete_state.set_value(int(self._started), [1.0])
        if rates is not None:
            discrete_state.set_value(int(self._rate), rates)
            discrete_state.set_value(int(self._inertia), inertia)
