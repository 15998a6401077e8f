//! The per-message loop of a node with one input: block on the input's event, hand every
//! message to a handler, stop at end of stream or on a termination request.

use crate::{is_eos, InSample, Input, Kit, KitError, Output};
use sonoflow_messages::WireMessage;
use std::time::Duration;

/// What a message handler wants next.
pub enum Flow {
    Continue,
    Stop,
}

/// Runs `f` on every message of `input` until end of stream, a stop from `f`, or a
/// termination request. Blocks on the input's event between messages (no polling).
/// Returns true if the stream ended normally (end-of-stream seen).
pub fn for_each<M, F>(kit: &mut Kit, input: &mut Input<M>, mut f: F) -> anyhow::Result<bool>
where
    M: WireMessage,
    F: FnMut(&mut Kit, &InSample<M>) -> anyhow::Result<Flow>,
{
    loop {
        while let Some(sample) = input.try_receive()? {
            if is_eos::<M>(sample.user_header()) {
                return Ok(true);
            }
            if let Flow::Stop = f(kit, &sample)? {
                return Ok(false);
            }
        }
        match kit.check_termination() {
            Ok(()) => {}
            Err(KitError::Terminated) => return Ok(false),
            Err(e) => return Err(e.into()),
        }
        input.wait(Duration::from_millis(200))?;
    }
}

/// The whole life of a node with one input and one output, after its handshake: runs `f` on
/// every message of `input` (counted in; `f` publishes on `out`, e.g. with
/// [`Kit::publish_copy`]) until end of stream or a termination request, then ends `out`'s stream
/// at the time of the last message received and finishes the node ([`Kit::finish_after`]).
pub fn transform<I, O, F>(mut kit: Kit, input: &mut Input<I>, out: &mut Output<O>, mut f: F) -> anyhow::Result<()>
where
    I: WireMessage,
    O: WireMessage,
    F: FnMut(&mut Kit, &mut Output<O>, &InSample<I>) -> anyhow::Result<()>,
{
    let mut last_t = 0.0;
    for_each(&mut kit, input, |kit, sample| {
        kit.stats.messages_in += 1;
        last_t = I::common(sample.user_header()).t_valid;
        f(kit, out, sample)?;
        Ok(Flow::Continue)
    })?;
    out.publish_eos(last_t)?;
    kit.finish_after(input)?;
    Ok(())
}

/// What a [`select_loop`] body wants next.
pub enum Step {
    /// Wait for the next message on any input, then call the body again.
    Continue,
    /// Every stream the node waits for has ended.
    Done,
}

/// How a [`select_loop`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SelectEnd {
    /// The body returned [`Step::Done`].
    Done,
    /// A termination request (SIGINT/SIGTERM) arrived; the body ran once more after it, so
    /// what had already arrived was taken.
    Terminated,
}

/// The event a node waits on for one input ([`crate::Input::wakeup`], [`crate::DynInput::wakeup`]).
#[derive(Clone)]
pub struct Wakeup(pub(crate) std::rc::Rc<iceoryx2::port::listener::Listener<iceoryx2::prelude::ipc::Service>>);

/// The loop of a node with several inputs: calls `body` (which takes whatever has arrived on any
/// input, without blocking), then blocks until a message arrives on one of `inputs` (or
/// `timeout` passes), and again, until `body` says [`Step::Done`] or a termination request
/// arrives. One WaitSet over the inputs' events: no polling.
pub fn select_loop<F>(kit: &mut Kit, inputs: &[Wakeup], timeout: Duration, mut body: F) -> anyhow::Result<SelectEnd>
where
    F: FnMut(&mut Kit) -> anyhow::Result<Step>,
{
    use iceoryx2::prelude::*;
    use iceoryx2::waitset::WaitSetRunResult;
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| KitError::Ipc { context: "creating the WaitSet".into(), detail: format!("{e:?}") })?;
    let mut guards = Vec::with_capacity(inputs.len());
    for w in inputs {
        guards.push(waitset.attach_notification(w.0.as_ref()).map_err(|e| KitError::Ipc {
            context: "attaching an input to the WaitSet".into(),
            detail: format!("{e:?}"),
        })?);
    }
    loop {
        if let Step::Done = body(kit)? {
            return Ok(SelectEnd::Done);
        }
        let t0 = std::time::Instant::now();
        let waited = waitset.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, timeout);
        crate::add_input_wait(t0);
        let terminated = match waited {
            Ok(WaitSetRunResult::TerminationRequest) | Ok(WaitSetRunResult::Interrupt) => true,
            Ok(_) => false,
            Err(e) => {
                return Err(KitError::Ipc { context: "waiting on the inputs".into(), detail: format!("{e:?}") }.into())
            }
        };
        for w in inputs {
            let _ = w.0.try_wait(|_| {});
        }
        if terminated || kit.check_termination().is_err() {
            let _ = body(kit)?;
            return Ok(SelectEnd::Terminated);
        }
    }
}
