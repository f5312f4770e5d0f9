"""The process model: how a program runs, boxed, watched and stopped (no Django here).

`launcher` builds a run's command line, `isolation` its box (namespaces, account, network),
`supervisor` runs it and captures its output, `watch` samples what the kernel does not count.
Like `rhal/` and `gateway/`, nothing here knows about programs as data or about the web.
"""

# Programs never see the server's virtualenv: interpreters are looked for on this path only.
SYSTEM_PATH = "/usr/local/bin:/usr/bin:/bin"
