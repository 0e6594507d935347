//! The physical constants a Brax config does not give: the ONE place where they are chosen.
//!
//! MEBEN.md section 1 takes geometry, joint axes and limits from the configs and physical
//! constants "in MuJoCo's style": masses from the config, inertia from the collider geometry,
//! armature and damping so that the default time step (0.01 s, 5 steps per 0.05 s control
//! step, `../shared/bench/SIM.md`) is stable, gear from `strength`. The table of values and
//! their reasons is repeated in `docs/SIMULATOR.md` ("Brax v1 configs").

/// Physical constants used when a Brax config becomes a simulator model.
#[derive(Clone, Debug, PartialEq)]
pub struct BraxPhysics {
    /// Armature of an actuated DoF per unit of actuator strength, in s^2 (kg m^2 per N m).
    ///
    /// Default 1/1000: the ant's joints (strength 350) get 0.35 kg m^2, the unimals'
    /// (150-300) 0.15-0.3. Reason: whatever the link inertia, a full-strength torque cannot
    /// change a joint velocity by more than `strength * dt / armature` = 10 rad/s in one 0.01 s
    /// step (0.1 rad of travel), which is Brax's own terminal joint speed
    /// (`strength / angular_damping` = 350 / 35 for the ant). Together with the damping below
    /// the joint velocity relaxes to `10 * action` rad/s within about one physics step, so
    /// the agents keep the agility they had in Brax (MuJoCo's ant, with armature 1 for gear
    /// 150 on 0.03 kg legs, is much slower) while no step can overshoot.
    pub armature_per_strength: f64,
    /// Armature of a DoF that no actuator drives (kg m^2). Default 0.1 (none in MeBen's files).
    pub passive_armature: f64,
    /// Joint damping = `damping_scale * angular_damping` of the config (N m s / rad).
    ///
    /// Default 1: Brax's relative angular damping is exactly a viscous joint damping in
    /// reduced coordinates (35 for the ant, 15-30 for the unimals). MeBen's files pair it with
    /// `strength` so that the terminal joint speed `strength / angular_damping` is 10 rad/s
    /// (claw 14, centipede torso 8.6); keeping it keeps that design. The simulator treats
    /// damping implicitly, so any value is stable.
    pub damping_scale: f64,
    /// Actuator gear = `gear_scale * strength` (N m at action 1). Default 1: `strength` is
    /// the torque at action 1 (MEBEN.md).
    pub gear_scale: f64,
    /// Control range of every motor. Default [-1, 1] (actions are clipped there, as in
    /// MuJoCo's ant and Brax).
    pub ctrlrange: [f64; 2],
    /// Coulomb friction of every geom. Default 1 (MuJoCo's ant and Brax's default).
    pub friction: f64,
    /// Whether Brax's capsule `end` (only one cap touches the ground plane) is passed to the
    /// simulator. Default true, as in Brax (the ant's feet are the `end: -1` caps).
    pub capsule_ends: bool,
}

impl Default for BraxPhysics {
    fn default() -> Self {
        BraxPhysics {
            armature_per_strength: 1.0 / 1000.0,
            passive_armature: 0.1,
            damping_scale: 1.0,
            gear_scale: 1.0,
            ctrlrange: [-1.0, 1.0],
            friction: 1.0,
            capsule_ends: true,
        }
    }
}

impl BraxPhysics {
    /// Armature of a DoF of a joint driven with this strength (`None`: passive joint).
    pub fn armature(&self, strength: Option<f64>) -> f64 {
        match strength {
            Some(s) => self.armature_per_strength * s,
            None => self.passive_armature,
        }
    }

    /// Damping of a DoF of a joint with this Brax `angular_damping`.
    pub fn damping(&self, angular_damping: f64) -> f64 {
        self.damping_scale * angular_damping
    }

    /// Gear of a motor with this Brax `strength`.
    pub fn gear(&self, strength: f64) -> f64 {
        self.gear_scale * strength
    }
}
