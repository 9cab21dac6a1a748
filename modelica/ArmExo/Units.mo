within ArmExo;
package Units "SI types used by the package (names as in Modelica.Units.SI)"
  extends ArmExo.Icons.Package;

  type Time = Real (final quantity = "Time", final unit = "s");
  type Angle = Real (final quantity = "Angle", final unit = "rad", displayUnit = "deg");
  type Angle_deg = Real (final quantity = "Angle", final unit = "deg") "Angle in degree";
  type AngularVelocity = Real (final quantity = "AngularVelocity", final unit = "rad/s");
  type AngularAcceleration = Real (final quantity = "AngularAcceleration", final unit = "rad/s2");
  type Torque = Real (final quantity = "Torque", final unit = "N.m");
  type Mass = Real (final quantity = "Mass", final unit = "kg", min = 0);
  type Length = Real (final quantity = "Length", final unit = "m");
  type Inertia = Real (final quantity = "MomentOfInertia", final unit = "kg.m2");
  type RotationalSpringConstant = Real (final quantity = "RotationalSpringConstant", final unit = "N.m/rad");
  type RotationalDampingConstant = Real (final quantity = "RotationalDampingConstant", final unit = "N.m.s/rad");
  type Acceleration = Real (final quantity = "Acceleration", final unit = "m/s2");
  type DimensionlessRatio = Real (final quantity = "DimensionlessRatio", final unit = "1");

  annotation (Documentation(info = "<html>
<p>Type definitions with the names and units of <code>Modelica.Units.SI</code>, so that the
package is self-contained (no Modelica Standard Library needed).</p>
</html>"));
end Units;
