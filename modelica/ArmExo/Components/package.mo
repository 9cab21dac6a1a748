within ArmExo;
package Components "The robot, the human arm and the joint friction"
  extends ArmExo.Icons.Package;
end Components;
