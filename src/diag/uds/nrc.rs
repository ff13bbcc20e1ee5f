//! Service identifiers and negative response codes of ISO 14229-1 (clause 8, table 2 for the
//! SIDs; annex A.1 for the NRCs; clause 7.5 for which NRCs a functional request suppresses).

/// The services the TCU serves (ISO 14229-1 clauses 10–14), by request SID.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Sid {
    /// 0x10 DiagnosticSessionControl (10.2).
    DiagnosticSessionControl,
    /// 0x11 ECUReset (10.3).
    EcuReset,
    /// 0x14 ClearDiagnosticInformation (12.2).
    ClearDiagnosticInformation,
    /// 0x19 ReadDTCInformation (12.3).
    ReadDtcInformation,
    /// 0x22 ReadDataByIdentifier (11.2).
    ReadDataByIdentifier,
    /// 0x27 SecurityAccess (10.4).
    SecurityAccess,
    /// 0x2E WriteDataByIdentifier (11.7).
    WriteDataByIdentifier,
    /// 0x31 RoutineControl (14.2).
    RoutineControl,
    /// 0x3E TesterPresent (10.5).
    TesterPresent,
}

impl Sid {
    /// The service of a request SID (`None`: not supported, NRC 0x11).
    pub fn from_request(sid: u8) -> Option<Sid> {
        Some(match sid {
            0x10 => Sid::DiagnosticSessionControl,
            0x11 => Sid::EcuReset,
            0x14 => Sid::ClearDiagnosticInformation,
            0x19 => Sid::ReadDtcInformation,
            0x22 => Sid::ReadDataByIdentifier,
            0x27 => Sid::SecurityAccess,
            0x2E => Sid::WriteDataByIdentifier,
            0x31 => Sid::RoutineControl,
            0x3E => Sid::TesterPresent,
            _ => return None,
        })
    }

    /// The request SID.
    pub fn request(self) -> u8 {
        match self {
            Sid::DiagnosticSessionControl => 0x10,
            Sid::EcuReset => 0x11,
            Sid::ClearDiagnosticInformation => 0x14,
            Sid::ReadDtcInformation => 0x19,
            Sid::ReadDataByIdentifier => 0x22,
            Sid::SecurityAccess => 0x27,
            Sid::WriteDataByIdentifier => 0x2E,
            Sid::RoutineControl => 0x31,
            Sid::TesterPresent => 0x3E,
        }
    }

    /// The positive response SID (request SID + 0x40).
    pub fn response(self) -> u8 {
        self.request() | 0x40
    }

    /// Whether the second byte is a sub-function (with the suppress-positive-response bit).
    pub fn has_sub_function(self) -> bool {
        !matches!(
            self,
            Sid::ClearDiagnosticInformation
                | Sid::ReadDataByIdentifier
                | Sid::WriteDataByIdentifier
        )
    }

    /// Whether the service needs a non-default session (NRC 0x7F in the default session).
    pub fn needs_extended_session(self) -> bool {
        matches!(
            self,
            Sid::SecurityAccess | Sid::WriteDataByIdentifier | Sid::RoutineControl
        )
    }
}

/// The negative response codes the TCU sends (`7F SID NRC`), ISO 14229-1 annex A.1. This is
/// also the error type of the UDS module: a service handler fails with the NRC to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum Nrc {
    #[error("serviceNotSupported (0x11)")]
    ServiceNotSupported,
    #[error("subFunctionNotSupported (0x12)")]
    SubFunctionNotSupported,
    #[error("incorrectMessageLengthOrInvalidFormat (0x13)")]
    IncorrectMessageLength,
    #[error("responseTooLong (0x14)")]
    ResponseTooLong,
    #[error("conditionsNotCorrect (0x22)")]
    ConditionsNotCorrect,
    #[error("requestSequenceError (0x24)")]
    RequestSequenceError,
    #[error("requestOutOfRange (0x31)")]
    RequestOutOfRange,
    #[error("securityAccessDenied (0x33)")]
    SecurityAccessDenied,
    #[error("invalidKey (0x35)")]
    InvalidKey,
    #[error("exceededNumberOfAttempts (0x36)")]
    ExceededNumberOfAttempts,
    #[error("requiredTimeDelayNotExpired (0x37)")]
    RequiredTimeDelayNotExpired,
    #[error("subFunctionNotSupportedInActiveSession (0x7E)")]
    SubFunctionNotSupportedInActiveSession,
    #[error("serviceNotSupportedInActiveSession (0x7F)")]
    ServiceNotSupportedInActiveSession,
}

impl Nrc {
    /// The NRC byte.
    pub fn code(self) -> u8 {
        match self {
            Nrc::ServiceNotSupported => 0x11,
            Nrc::SubFunctionNotSupported => 0x12,
            Nrc::IncorrectMessageLength => 0x13,
            Nrc::ResponseTooLong => 0x14,
            Nrc::ConditionsNotCorrect => 0x22,
            Nrc::RequestSequenceError => 0x24,
            Nrc::RequestOutOfRange => 0x31,
            Nrc::SecurityAccessDenied => 0x33,
            Nrc::InvalidKey => 0x35,
            Nrc::ExceededNumberOfAttempts => 0x36,
            Nrc::RequiredTimeDelayNotExpired => 0x37,
            Nrc::SubFunctionNotSupportedInActiveSession => 0x7E,
            Nrc::ServiceNotSupportedInActiveSession => 0x7F,
        }
    }

    /// Whether a functional request answers with silence instead of this NRC (ISO 14229-1 7.5).
    pub fn suppressed_on_functional(self) -> bool {
        matches!(
            self,
            Nrc::ServiceNotSupported
                | Nrc::SubFunctionNotSupported
                | Nrc::RequestOutOfRange
                | Nrc::SubFunctionNotSupportedInActiveSession
                | Nrc::ServiceNotSupportedInActiveSession
        )
    }

    /// The negative response `7F SID NRC` to a request with SID `sid`.
    pub fn response(self, sid: u8) -> Vec<u8> {
        vec![0x7F, sid, self.code()]
    }
}
