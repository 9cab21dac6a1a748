within ArmExo;
package Interfaces "Partial models: the interfaces the components extend"
  extends ArmExo.Icons.Package;
end Interfaces;
