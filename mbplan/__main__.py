from mbplan.cli.main import console

console()
