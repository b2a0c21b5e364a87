"""Frontend plugins (image sources); installed as `eas_vo.frontends`."""
