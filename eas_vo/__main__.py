from eas_vo.cli.main import main

raise SystemExit(main())
