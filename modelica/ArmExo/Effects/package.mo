within ArmExo;
package Effects "Unmodelled effects of docs/spec/effects.md that live in the plant (each off by default)"
  extends ArmExo.Icons.Package;
  annotation (Documentation(info = "<html>
<p>Each effect is off with its default parameters (0, or scale 1). Component names in
<a href=\"modelica://ArmExo.ArmExoPlant\">ArmExoPlant</a> equal the effect names of the catalogue,
so parameters read e.g. <code>actuator_lag.time_constant_s</code>.</p>
</html>"));
end Effects;
