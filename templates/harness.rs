{#- Appended to the atomic component's module (templates/atomic.rs), in rustfmt's
    layout: coolc/src/layout.rs (`l`) lays out the description-dependent lines. -#}

/// The result of a [`Harness`] operation.
pub type HarnessResult<T> = ::core::result::Result<T, ::coolbot::harness::HarnessError>;

/// `{{ c.type_name }}` alone for tests: built with in-memory ports on a virtual clock
/// of its own and driven on the caller's thread, exactly as its component thread
/// would run it (`coolbot::harness`). Feed its inputs with its own packet types,
/// advance the clock, and read back what it sent, its variables, configuration and
/// behaviour, and its default and user states.
pub struct Harness<B> {
    inner: ::coolbot::harness::Harness,
    behavior: ::core::marker::PhantomData<fn() -> B>,
}

impl<B: Behavior> Harness<B> {
    /// Builds the component around `behavior` and runs its `start` hook: it is then
    /// `ready` (or `starting_error`); [`Harness::run`] runs the user automaton.
    pub fn new(behavior: B) -> HarnessResult<Self> {
        Self::with(behavior, Config::default(), Vars::default())
    }

    /// Like [`Harness::new`], from the given configuration and variables.
    pub fn with(behavior: B, config: Config, vars: Vars) -> HarnessResult<Self> {
        let component = component_with(SPEC.type_name, behavior, config, vars);
        let inner = ::coolbot::harness::Harness::new(component)?;
        Ok(Harness {
            inner,
            behavior: ::core::marker::PhantomData,
        })
    }

    /// [`Harness::new`], then `running`: the initial user state is entered.
    pub fn running(behavior: B) -> HarnessResult<Self> {
        let mut harness = Self::new(behavior)?;
        harness.inner.run()?;
        Ok(harness)
    }

    /// The untyped harness: commands, the clock, the monitoring snapshot.
    pub fn inner(&mut self) -> &mut ::coolbot::harness::Harness {
        &mut self.inner
    }

    /// Runs the component until nothing more is due at the current time.
    pub fn settle(&mut self) -> HarnessResult<()> {
        self.inner.settle()
    }

    /// Moves the virtual clock forward by `by`, timer by timer, settling at each.
    pub fn advance(&mut self, by: ::core::time::Duration) -> HarnessResult<()> {
        self.inner.advance(by)
    }

    /// Commands `running` through the control port.
    pub fn run(&mut self) -> HarnessResult<()> {
        self.inner.run()
    }

    /// The default automaton's state.
    pub fn state(&self) -> ::coolbot::State {
        self.inner.state()
    }

    /// The user automaton's state, while it has one.
    pub fn user_state(&self) -> ::core::option::Option<UserState> {
        let name = self.inner.user_state()?;
        UserState::ALL
            .into_iter()
            .find(|state| state.name() == name)
    }

    /// The task result.
    pub fn result(&self) -> ::coolbot::TaskResult {
        self.inner.result()
    }

    /// The last error.
    pub fn error(&self) -> ::core::option::Option<::std::string::String> {
        self.inner.error()
    }

    /// The quality level (0 = best).
    pub fn quality(&self) -> usize {
        self.inner.quality()
    }

    /// The component's variables: observable, controllable and local.
    pub fn vars(&self) -> &Vars {
        &self.glue().vars
    }

    /// The current configuration.
    pub fn config(&self) -> &Config {
        &self.glue().config
    }

    /// The behaviour.
    pub fn behavior(&self) -> &B {
        &self.glue().behavior
    }

    /// The behaviour, mutable (between steps).
    pub fn behavior_mut(&mut self) -> &mut B {
        match self.inner.automaton_mut::<__CoolGlue<B>>() {
            Some(glue) => &mut glue.behavior,
            None => unreachable!("a harness of this module runs this module's glue"),
        }
    }

    fn glue(&self) -> &__CoolGlue<B> {
        match self.inner.automaton::<__CoolGlue<B>>() {
            Some(glue) => glue,
            None => unreachable!("a harness of this module runs this module's glue"),
        }
    }
{%- for m in h.inputs %}
{{ "" }}
{{- l.harness_method(&m.doc, &m.signature, &m.body) }}
    }
{%- endfor %}
{%- for m in h.outputs %}
{{ "" }}
{{- l.harness_method(&m.doc, &m.signature, &m.body) }}
    }
{%- endfor %}
{%- for m in h.setters %}
{{ "" }}
{{- l.harness_method(&m.doc, &m.signature, &m.body) }}
    }
{%- endfor %}
}
