"""The robot's side of the conversation: what the agent does with the dialogue's intents.

:mod:`~agent.conversation.agent` (:class:`~agent.conversation.agent.DialogueAgent`: intents
in, answers, questions and base commands out; follow-me), :mod:`~agent.conversation.memory`
(what the robot was told, kept in the conceptual map) and :mod:`~agent.conversation.task`
(the asyncio task that connects it to the bus). The dialogue process itself (speech text to
intents and back) is :mod:`agent.dialogue`, a separate process.
"""
