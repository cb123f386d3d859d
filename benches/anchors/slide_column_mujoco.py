"""MuJoCo anchor for benches/sim_step.rs (issue 15): the slide_column moving body as one MuJoCo body on
six joints -- the x slide driven by a position servo (MuJoCo `position` actuator, kp = kv_vel * kp_pos,
kv = kv_vel, the PD form of vmt's position + velocity loop) and y, z, roll, pitch, yaw held by the four
bearing blocks' stiffness and damping lumped about the centre of mass (numbers computed by the bench
from vmt's model and passed on the command line) -- stepped with mj_step(nstep) along a constant-feed
command at vmt's time step. Prints one line: `us_per_step=<median of the chunks>`.

usage: python3 slide_column_mujoco.py STEPS MASS IXX IYY IZZ KY KZ KRX KRY KRZ CY CZ CRX CRY CRZ KP KV FEED DT
"""
import sys
import time

import mujoco


def main(argv):
    steps = int(argv[0])
    (mass, ixx, iyy, izz, ky, kz, krx, kry, krz, cy, cz, crx, cry, crz, kp, kv, feed, dt) = map(float, argv[1:])
    xml = f"""
<mujoco>
  <option timestep="{dt}" integrator="Euler"/>
  <worldbody>
    <body name="slide">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0" stiffness="{ky}" damping="{cy}"/>
      <joint name="z" type="slide" axis="0 0 1" stiffness="{kz}" damping="{cz}"/>
      <joint name="rx" type="hinge" axis="1 0 0" stiffness="{krx}" damping="{crx}"/>
      <joint name="ry" type="hinge" axis="0 1 0" stiffness="{kry}" damping="{cry}"/>
      <joint name="rz" type="hinge" axis="0 0 1" stiffness="{krz}" damping="{crz}"/>
      <inertial pos="0 0 0" mass="{mass}" diaginertia="{ixx} {iyy} {izz}"/>
    </body>
  </worldbody>
  <actuator>
    <position joint="x" kp="{kp}" kv="{kv}" ctrllimited="false"/>
  </actuator>
</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    chunk = 1000
    times = []
    x = 0.2
    data.qpos[0] = x
    done = 0
    while done < steps:
        n = min(chunk, steps - done)
        # The command advances along the feed; updated once per chunk (python overhead kept out).
        x += feed * dt * n
        data.ctrl[0] = x
        t0 = time.perf_counter()
        mujoco.mj_step(model, data, nstep=n)
        times.append((time.perf_counter() - t0) / n * 1e6)
        done += n
    times.sort()
    print(f"us_per_step={times[len(times) // 2]}")


if __name__ == "__main__":
    main(sys.argv[1:])
