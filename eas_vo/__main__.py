from eas_vo.cli import main

raise SystemExit(main())
