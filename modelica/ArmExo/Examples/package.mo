within ArmExo;
package Examples "Example experiments (inputs defined inside, so that any tool can run them)"
  extends ArmExo.Icons.Package;
end Examples;
