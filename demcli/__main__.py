from demcli.cli import main

main()
