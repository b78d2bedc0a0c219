"""One dock widget per method. Every panel derives from :class:`app.panels.base.MethodPanel`."""
