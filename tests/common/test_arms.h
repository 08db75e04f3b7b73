// Small inline arms shared by the suites that need a MuJoCo truth without a model file.
#pragma once

#include <string>

namespace flexbench::testing {

// A 3-joint arm with masses (a yawing base, two pitching links) and a site "ee" at the fore
// link's end; with `servos`, a position servo on every joint, for a truth its servos settle.
inline std::string Arm3Mjcf(bool servos = false) {
  std::string xml = R"(
<mujoco model="arm3">
  <compiler angle="radian" autolimits="true"/>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <joint name="j1" axis="0 0 1"/>
      <geom type="cylinder" size="0.05 0.05" mass="2"/>
      <body name="upper" pos="0 0 0.1">
        <joint name="j2" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.03" mass="3"/>
        <body name="fore" pos="0.4 0 0">
          <joint name="j3" axis="0 1 0"/>
          <geom type="capsule" fromto="0 0 0 0.35 0 0" size="0.025" mass="2"/>
          <site name="ee" pos="0.35 0 0.02"/>
        </body>
      </body>
    </body>
  </worldbody>)";
  if (servos) {
    xml += R"(
  <actuator>
    <position name="a1" joint="j1" kp="2000"/>
    <position name="a2" joint="j2" kp="2000"/>
    <position name="a3" joint="j3" kp="2000"/>
  </actuator>)";
  }
  return xml + "\n</mujoco>";
}

}  // namespace flexbench::testing
